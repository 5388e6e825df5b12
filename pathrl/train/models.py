"""The name under which run configs (``agent.actor.class_name: pathrl.train.models:MixedPrecisionMLPModel``) find
the mixed-precision policy network for RSL-RL; it lives in :mod:`pathrl.policy.models`."""

from pathrl.policy.models import MixedMLP, MixedPrecisionMLPModel

__all__ = ["MixedMLP", "MixedPrecisionMLPModel"]
