"""Distillation: a model-based controller teaches the policy network (rsl-rl ``Distillation``, DAgger style).

The student (the policy network, with the policy's own observation layout) acts; the teacher labels every
state it visits with the action it would take there, and the student regresses onto those labels (MSE on
the mean action). RSL-RL 5.5.1 expects a teacher *network* that reads a group of the observation
TensorDict. Our teachers are controllers that need the env itself (path, time law, robot state), so
:class:`TeacherLabels` wraps the env and adds the controller's action as the observation group
``"teacher"``, and :class:`ControllerTeacher` is the rsl-rl model that returns that group. The controller
runs exactly once per env step, on the state the student is about to act in.

A distillation run's checkpoints hold ``student_state_dict``; ``init_from=<distillation run>`` starts a PPO
run from the student (:func:`pathrl.train.warm_start.warm_start`), with a new critic.
"""

from __future__ import annotations

from collections.abc import Callable

from tensordict import TensorDict
from torch import Tensor, nn

from pathrl.envs.tracking import PathTrackingEnv
from pathrl.policy.residual import ControllerObs

__all__ = ["ControllerTeacher", "TEACHER_GROUP", "TeacherLabels"]

#: Observation group that carries the teacher's action.
TEACHER_GROUP = "teacher"


class TeacherLabels(ControllerObs):
    """A :class:`PathTrackingEnv` whose observations also hold ``controller(obs)`` (N, num_actions) as the group
    ``"teacher"``. Everything else is the wrapped env's."""

    def __init__(self, env: PathTrackingEnv, controller: Callable[[TensorDict], Tensor]):
        super().__init__(env, controller, TEACHER_GROUP)


class ControllerTeacher(nn.Module):
    """rsl-rl teacher model (the ``MLPModel`` interface) whose action is the observation group ``"teacher"``
    that :class:`TeacherLabels` fills. It has no parameters; its (empty) state dict loads trivially."""

    is_recurrent = False

    def __init__(self, obs: TensorDict, obs_groups: dict[str, list[str]], obs_set: str, output_dim: int,
                 **_: object) -> None:
        super().__init__()
        if obs_groups[obs_set] != [TEACHER_GROUP]:
            raise ValueError(f"ControllerTeacher reads the observation group {TEACHER_GROUP!r}; "
                             f"obs_groups.{obs_set} is {obs_groups[obs_set]}")
        if obs[TEACHER_GROUP].shape[-1] != output_dim:
            raise ValueError(f"teacher labels have {obs[TEACHER_GROUP].shape[-1]} actions, the env {output_dim}")

    def forward(self, obs: TensorDict, masks: Tensor | None = None, hidden_state: object = None,
                stochastic_output: bool = False) -> Tensor:
        """The teacher's action: the observation group ``teacher`` (N, A)."""
        return obs[TEACHER_GROUP]

    def reset(self, dones: Tensor | None = None, hidden_state: object = None) -> None:
        """Nothing to reset (not recurrent)."""
        pass

    def get_hidden_state(self) -> None:
        """None (not recurrent)."""
        return None

    def detach_hidden_state(self, dones: Tensor | None = None) -> None:
        """Nothing to detach (not recurrent)."""
        pass
