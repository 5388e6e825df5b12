"""The iterative waypoint adjustment as an episodic environment for the learned policy (paper Alg. 2 / 3).

One episode = one target trajectory at one speed command. ``reset`` executes the baseline profile (m MoveL
waypoints) and returns the (m, 313) local features; ``step(actions)`` moves every waypoint by its action
(eq. 14), executes the new profile once and returns the next features, the per-waypoint rewards and local
termination flags (eqs. 15-18) and the global termination (paper Sec. IV-B): failure (max error > 5 mm or the
path leaves the arm's reach / axis ranges), success (max error < 0.25 mm) or k >= k_max. numpy only; the
learner batches the m waypoints as m transitions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pathrl.industrial import arm
from pathrl.industrial.controller import ControllerParams, execute
from pathrl.industrial.features import (
    FAIL_MM,
    SUCCESS_MM,
    action_steps,
    features,
    local_max,
    match,
    rewards,
)
from pathrl.industrial.metrics import Errors, evaluate
from pathrl.industrial.program import DEFAULT_SEED, Program
from pathrl.industrial.trajectories import Target, baseline_program, waypoint_indices

__all__ = ["IWAEpisode", "IWASettings", "StepResult"]


@dataclass
class StepResult:
    """What one IWA iteration returns: next features (m, 313), rewards (m,), local done flags (m,), global
    termination, and the execution's errors (None if the profile could not be executed)."""

    obs: np.ndarray
    reward: np.ndarray
    done: np.ndarray
    terminal: bool
    errors: Errors | None


@dataclass(frozen=True)
class IWASettings:
    """One IWA episode's settings: the baseline profile of `m` MoveL waypoints with zone `zone` (mm), at most `k_max`
    iterations, actions clipped to +-`action_clip` (the paper's 2), the reward weight `w_ori` of the orientation
    improvement and the success reward's factor `success_decay` ^ k at iteration k."""

    m: int = 100
    zone: float = 10.0
    k_max: int = 10
    action_clip: float = 2.0
    w_ori: float = 1.0
    success_decay: float = 1.0


class IWAEpisode:
    """IWA on one target at speed command `v` (mm/s) with `settings` (module doc)."""

    def __init__(self, target: Target, v: float, controller: ControllerParams | None = None,
                 settings: IWASettings = IWASettings()) -> None:
        self.target, self.v, self.k_max = target, float(v), int(settings.k_max)
        self.action_clip, self.w_ori = float(settings.action_clip), float(settings.w_ori)
        self.success_decay = float(settings.success_decay)
        self.controller = ControllerParams() if controller is None else controller
        self.m, self.zone = settings.m, settings.zone
        self.psi = waypoint_indices(len(target.p), settings.m)

    def _observe(self, program: Program) -> tuple[np.ndarray, Errors, np.ndarray, np.ndarray]:
        ex = execute(program, self.v, self.controller)
        errs = evaluate(ex.p, ex.rot, 1.0 / self.controller.rate, self.target.p, self.target.z_axis)
        matched = match(self.target.p, self.target.z_axis, ex.p, ex.rot[:, :, 2])
        q_wp = arm.ik_path(program.positions, program.rotations, DEFAULT_SEED)
        self._err = matched.err[self.psi]
        pos, ori = local_max(matched, self.psi)
        return features(self.target.p, self.psi, matched, q_wp), errs, pos, ori

    def reset(self) -> np.ndarray:
        """Execute the baseline profile; returns its features (m, 313)."""
        self.program = baseline_program(self.target, self.m, self.zone)
        self.k = 0
        obs, self.errors, self.pos0, self.ori0 = self._observe(self.program)
        self.pos, self.ori = self.pos0, self.ori0
        self.best = (self.errors.max_pos_mm, self.program, self.errors)
        return obs

    def step(self, actions: np.ndarray) -> StepResult:
        """Apply actions (m, 3) (clipped to +-action_clip; the paper's +-2), execute, observe (module doc)."""
        actions = np.clip(np.asarray(actions, dtype=np.float64), -self.action_clip, self.action_clip)
        program = self.program.with_positions(self.program.positions + action_steps(actions, self.program.positions,
                                                                                   self._err))
        self.k += 1
        try:
            obs, errs, pos, ori = self._observe(program)
        except ValueError:  # out of reach or axis range: a failure, the profile stays as it was
            fail = np.full(self.m, True)
            return StepResult(np.zeros((self.m, 313)), np.full(self.m, -100.0), fail, True, None)
        reward, done = rewards(pos, ori, self.pos, self.ori, self.pos0, self.ori0, self.w_ori,
                               self.success_decay ** self.k)
        self.program, self.errors, self.pos, self.ori = program, errs, pos, ori
        if errs.max_pos_mm < self.best[0]:
            self.best = (errs.max_pos_mm, program, errs)
        terminal = errs.max_pos_mm > FAIL_MM or errs.max_pos_mm < SUCCESS_MM or self.k >= self.k_max
        return StepResult(obs, reward, done, bool(terminal), errs)
