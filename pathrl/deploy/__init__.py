"""Deployment: a trained policy in a robot's control loop (:class:`Follower`) and exported actors."""

from pathrl.deploy.follower import Follower, FollowerError, PreparedPath, Setpoints

__all__ = ["Follower", "FollowerError", "PreparedPath", "Setpoints"]
