"""Controller actions in the observation, and residual policies on top of a controller.

:class:`ControllerObs` wraps a :class:`~pathrl.envs.tracking.PathTrackingEnv` so that its observation also holds a
model-based controller's action for the current state, as an observation group. Distillation uses it to label
states with the teacher's action (group ``"teacher"``); a residual run (``residual: {scale, controller}`` in the
run config) uses it for the base action the network corrects (group ``"base"``):

    action = clip(base + scale * residual, -1, 1)          (N, num_actions), the env's action space

The env's valid acceleration range maps that action, so every limit holds whatever the network outputs. The
network's last layer starts at zero, so an untrained residual policy *is* the controller.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from tensordict import TensorDict
from torch import Tensor, nn

__all__ = ["BASE_GROUP", "ControllerObs", "ResidualEnv", "ResidualPolicy", "check_residual_cfg", "compose",
           "zero_last_layer"]


#: Observation group of a residual policy's base action.
BASE_GROUP = "base"


def compose(base: Tensor, residual: Tensor, scale: float) -> Tensor:
    """The env action (N, A) of a base action (N, A) and a residual (N, A), both in [-1, 1] units."""
    return (base + scale * residual).clamp(-1.0, 1.0)


class ControllerObs:
    """An env whose observations also hold ``controller(obs)`` (N, num_actions) as the group `group`.

    The controller may be stateful (a re-planned time law): it runs exactly once per env state, on the state the
    policy is about to act in. Everything else is the wrapped env's.
    """

    def __init__(self, env: Any, controller: Callable[[TensorDict], Tensor], group: str):
        self.env, self.controller, self.group = env, controller, group
        self._steps, self._labelled_at = 0, -1
        self._label: Tensor | None = None

    def __getattr__(self, name: str):
        return getattr(self.env, name)

    def label(self, obs: TensorDict) -> Tensor:
        """The controller's action (N, num_actions) float32 for the current state (computed once per state)."""
        if self._labelled_at != self._steps:
            self._label = self.controller(obs).to(torch.float32)
            self._labelled_at = self._steps
        return self._label

    def state_dict(self) -> dict[str, Any]:
        """What a resume needs to continue exactly: the controller's changing tensors (its plan, its last
        correction) and the label of the current state."""
        tensors = {k: v.clone() for k, v in vars(self.controller).items() if isinstance(v, Tensor)}
        label = None if self._label is None or self._labelled_at != self._steps else self._label.clone()
        return {"controller": tensors, "label": label}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Put a :meth:`state_dict` back (into a wrapper built from the same config), each tensor onto the device
        of the one it replaces (the label: the env's)."""
        for name, value in state["controller"].items():
            cur = getattr(self.controller, name, None)
            if not isinstance(cur, Tensor):
                raise ValueError(f"controller state: {name} is not a tensor of this controller")
            setattr(self.controller, name, value.to(cur.device))  # a checkpoint loads to the CPU; the env may not
        label = state["label"]
        self._label = None if label is None else label.to(getattr(self.env, "device", label.device))
        self._labelled_at = self._steps if label is not None else -1

    def _with_label(self, obs: TensorDict) -> TensorDict:
        obs[self.group] = self.label(obs)
        return obs

    def get_observations(self) -> TensorDict:
        """The env's observations with the controller's action added."""
        return self._with_label(self.env.get_observations())

    def step(self, actions: Tensor) -> tuple[TensorDict, Tensor, Tensor, dict]:
        """Step the env; (obs with the controller's action, rewards, dones, extras)."""
        obs, rewards, dones, extras = self.env.step(actions)
        self._steps += 1
        return self._with_label(obs), rewards, dones, extras


class ResidualEnv(ControllerObs):
    """The env a residual policy trains in: its actions are residuals on the controller's (group ``"base"``)."""

    def __init__(self, env: Any, controller: Callable[[TensorDict], Tensor], scale: float):
        super().__init__(env, controller, BASE_GROUP)
        self.scale = float(scale)

    def step(self, actions: Tensor) -> tuple[TensorDict, Tensor, Tensor, dict]:
        """Step with the controller's action plus ``scale`` times the residual `actions` (N, A), clamped to [-1, 1]."""
        base = self.label(self.env.get_observations())
        return super().step(compose(base, actions, self.scale))


class ResidualPolicy(nn.Module):
    """Deterministic residual policy for evaluation: obs (the env's TensorDict) -> env actions (N, A)."""

    def __init__(self, controller: Callable[[TensorDict], Tensor], actor: nn.Module, scale: float):
        super().__init__()
        self.controller, self.actor, self.scale = controller, actor, float(scale)

    def forward(self, obs: TensorDict) -> Tensor:
        """Env actions (N, A): the controller's plus the actor's residual."""
        base = self.controller(obs).to(torch.float32)
        obs[BASE_GROUP] = base
        return compose(base, self.actor(obs), self.scale)


def check_residual_cfg(spec: dict[str, Any]) -> tuple[float, dict[str, Any]]:
    """(scale, controller spec) of a run config's ``residual`` entry; ValueError naming the bad key."""
    if set(spec) != {"scale", "controller"}:
        raise ValueError(f"residual: expected the keys ['controller', 'scale'], got {sorted(spec)}")
    scale = spec["scale"]
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not 0.0 < float(scale) <= 2.0:
        raise ValueError(f"residual.scale must be a number in (0, 2], got {scale!r}")
    if not isinstance(spec["controller"], dict):
        raise ValueError("residual.controller must be a controller spec ({name: tray, ...})")
    return float(scale), spec["controller"]


def zero_last_layer(model: nn.Module) -> None:
    """Zero the weights and bias of the model's last linear layer: its mean output starts at 0."""
    last = [m for m in model.modules() if isinstance(m, nn.Linear)][-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.zero_()
