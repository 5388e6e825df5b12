"""Policy networks and how a run config names them."""

from typing import Any

from pathrl.policy.models import MixedPrecisionMLPModel

__all__ = ["MixedPrecisionMLPModel", "policy_role"]


def policy_role(agent: dict[str, Any]) -> str:
    """The key of the policy network in an RSL-RL train cfg: ``student`` (distillation) or ``actor`` (PPO)."""
    return "student" if "student" in agent else "actor"
