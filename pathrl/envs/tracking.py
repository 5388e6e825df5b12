"""Batched path-tracking environment (pure kinematics, torch), implementing rsl-rl's ``VecEnv``.

MDP (paper, Sec. III; original_pathtracking.md 3-7):
  state   commanded joint position / velocity / acceleration (normalized), the knot window
          (N knots: the knot at/behind the robot and N-1 ahead), the position inside the current knot
          interval, the path length covered by the window, the distance of each window knot.
          Knots are given relative to the robot's position by default (``knot_obs=relative``: the
          policy sees the direction to each knot directly, which trains much faster); the paper's
          absolute knot positions are ``knot_obs=absolute``. With ``end_obs`` the state also holds the
          vector from the robot to the segment's end knot and the arc length left, both scaled by the knot
          gap D (clipped to [-1, 1]): seen at the window's scale (K D) the last centimetres vanish, and a
          deterministic policy could come to rest just short of the end. The observation's terms (state,
          feedback, tcp), their fixed order and column layout: :mod:`pathrl.envs.observations`,
          ``env.observation_layout()``.
  action  one value in [-1, 1] per joint, mapped into the valid acceleration range for the end of the
          next 0.1 s step (jerk/acceleration/velocity/position limits, braking stays possible).
  reward  sum of weighted terms (pathrl.envs.rewards): path length R_l and deviation R_d (+ task terms).
  task    optional sensory feedback (pathrl.sim.feedback, e.g. a ball on a plate): it sees the step's
          control-rate setpoints, adds its sensor values to the state (``feedback_obs``), named values
          for task reward terms, and a failure (ball off the plate) that ends the episode
          (``fail_terminates``).
  tcp     optional (``tcp_obs``; the authors' ball experiments): per TCP the reference TCP position at the
          current arc length, normalized in ``tcp_obs_box``, and reference minus commanded TCP position over
          ``tcp_obs_error``; last in the state (after the feedback), so a warm start appends them.

Fixed step order (per env, batched; every tensor is (N, ...)):
  1. clip actions; a1 = a_min + (1 + action) / 2 (a_max - a_min); envs in braking mode use the braking law.
     Joints outside the path (ARMAR-4's legs) map action 0 to the admissible acceleration nearest 0
     (``free_joint_actions=centred``, :func:`~pathrl.limits.feasible.action_to_acceleration`), so a new
     joint with zero output weights holds still: a knee at rest on its limit would otherwise accelerate.
     ``posture`` adds a critically damped pull back to the start posture: acceleration is a double
     integrator, and without it a small bias of a leg action (0.01) drifts the leg by 0.5 rad in 6 s.
  2. integrate with linearly interpolated acceleration: `substeps` intermediate positions + end state.
  3. progress: arc length L_a of the polyline through the step's positions (path joints).
  4. deviation: each intermediate position vs the reference at the same arc length from the step start.
  5. feedback (if any) follows the step's control-rate setpoints; reward terms from (L_a, l_State,
     deviations, action, feedback values); path position s += L_a (clipped at the end).
  6. reaching the end switches to braking from the next step; "stopped" (|v|, |a| < tol after braking)
     terminates; the step budget truncates (time out); optional deviation threshold and task failure
     terminate.
     The end counts as reached when the covered arc length reaches the end knot's, or (``end_tolerance``)
     when the robot is within that weighted joint distance of the end knot with less than one knot gap D
     of arc length left: a path that cuts corners arrives with arc length to spare, and could otherwise
     only "finish" by wandering around the end knot.
  7. terminating by a stop multiplies that step's reward by the remaining budget (paper: finishing
     early is never worse than idling to the time limit).
  8. finished envs are reset (new path segment); observations are built for all envs.
"""

from __future__ import annotations

import math
from dataclasses import asdict

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl import native
from pathrl.envs import terminations as terms
from pathrl.envs.observations import (
    active_terms,
    assemble,
    critic_observation,
    observation_layout,
    tcp_distance,
    tracking_state,
)
from pathrl.envs.rewards import ENV_VALUES, TASK_VALUES, RewardTerm, StepQuantities
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.backend import current, env_scoped
from pathrl.limits.braking import braking_within
from pathrl.limits.feasible import (
    JointLimits,
    acceleration_to_action,
    action_to_acceleration,
    valid_acceleration_range,
)
from pathrl.limits.integrate import end_of_step, interpolate_step
from pathrl.limits.kernels import kernel
from pathrl.paths.inside import INSIDE_TOL, table_excess
from pathrl.paths.pathset import PathSet, table_position
from pathrl.paths.segments import Segments, full_segments, sample_segments
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec
from pathrl.sim.feedback import Feedback

try:  # rsl-rl is a training dependency; the env works without it (evaluation, tests).
    from rsl_rl.env import VecEnv as _VecEnvBase
except ImportError:  # pragma: no cover
    _VecEnvBase = object


__all__ = ["PathTrackingEnv", "advance"]


@kernel(static=True)
def advance(pos: Tensor, vel: Tensor, acc: Tensor, a1: Tensor, path_index: Tensor, s: Tensor, end_s: Tensor,
            path: Tensor, table: Tensor, length: Tensor, dev_weights: Tensor, dt: float, substeps: int,
            table_step: float) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Steps 2-4 of the step order for N envs: the end state and the step's progress and deviation.

    pos, vel, acc, a1: (N, D) state and end acceleration; path_index: (M,) path joints; s, end_s: (N,)
    arc length now and at the segment end; path: (N,) path ids into table (P, S, M) / length (P,);
    dev_weights: (M,). Returns p1, v1 (N, D), moved (N,) polyline arc length of the `substeps`
    intermediate positions (path joints), dev_max and dev_mean (N,): weighted distance of each
    intermediate position to the reference at the same arc length from the step start (clamped at
    the segment end), max and arc-length weighted mean (plain mean when the robot does not move).
    """
    q_sub, _, _ = interpolate_step(pos, vel, acc, a1, dt, substeps)
    q_sub = q_sub.index_select(2, path_index)  # (N, S, M)
    p1, v1 = end_of_step(pos, vel, acc, a1, dt)
    q_prev = torch.cat([pos.index_select(1, path_index).unsqueeze(1), q_sub[:, :-1]], dim=1)
    seg_len = (q_sub - q_prev).norm(dim=2)  # (N, S)
    cum = seg_len.cumsum(dim=1)
    moved = cum[:, -1]
    s_ref = torch.minimum(s.unsqueeze(1) + cum, end_s.unsqueeze(1))
    ref = table_position(table, length, table_step, path, s_ref)
    dev = ((ref - q_sub) * dev_weights).norm(dim=2)  # (N, S)
    dev_max = dev.amax(dim=1)
    dev_mean = torch.where(moved > 1e-12, (dev * seg_len).sum(1) / moved.clamp(min=1e-12), dev.mean(dim=1))
    return p1, v1, moved, dev_max, dev_mean


def _values_read(reward_terms: list[RewardTerm], feedback: Feedback | None) -> set[str]:
    """The task values the reward terms read; ValueError for a term whose values neither the feedback source nor
    the env (:data:`ENV_VALUES`) provides."""
    have = (set(feedback.value_names) if feedback is not None else set()) | set(ENV_VALUES)
    read: set[str] = set()
    for t in reward_terms:
        needs = TASK_VALUES.get(t.fn.__name__, ())
        missing = [v for v in needs if v not in have]
        if missing:
            raise ValueError(f"reward term {t.name!r} needs a task feedback providing {missing} "
                             "(e.g. task=ball_on_plate)")
        read.update(needs)
    return read


class PathTrackingEnv(_VecEnvBase):
    """N robots tracking reference path segments in parallel."""

    def __init__(self, cfg: TrackingEnvCfg, robot: RobotSpec, paths: PathSet, reward_terms: list[RewardTerm],
                 feedback: Feedback | None = None, fk: ForwardKinematics | None = None) -> None:
        self.cfg, self.limit_backend = cfg, cfg.limit_backend  # limit code of steps (None: the one in effect)
        self.feedback = feedback
        self._fk = fk  # the env's one kinematics object (shared with its feedback), built on first use (self.fk)
        self.control_steps = int(round(cfg.control_rate * cfg.dt))
        self.robot = robot
        self.device = torch.device(cfg.device)
        self.num_envs = n = cfg.num_envs
        self.num_actions = robot.dof
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(cfg.seed)
        self.limits = JointLimits.from_robot(robot, device=self.device)
        self.reward_terms = reward_terms
        self.tcp_reward = "tcp_dev" in _values_read(reward_terms, feedback)
        self.path_index = torch.as_tensor(robot.path_index, device=self.device)
        self.set_paths(paths)
        self.hold = torch.ones(robot.dof, dtype=torch.bool, device=self.device)  # joints mapped around 0
        self.hold[self.path_index] = False
        if cfg.free_joint_actions == "linear":
            self.hold[:] = False
        self.knot_gap = float(cfg.knot_gap_norm or self.paths.max_knot_gap())
        self.horizon = (cfg.n_state - 1) * self.knot_gap
        w = torch.as_tensor(robot.deviation_weights, dtype=torch.float64, device=self.device)
        self.dev_weights = w * math.sqrt(len(w) / float((w**2).sum()))
        self.max_episode_length = int(math.ceil(cfg.episode_budget_s / cfg.dt)) + 1
        self.tcp_box = None
        if cfg.tcp_obs:
            box = torch.as_tensor(cfg.tcp_obs_box, dtype=torch.float64, device=self.device)
            if box.shape != (6,) or not bool((box[1::2] > box[0::2]).all()) or not cfg.tcp_obs_error > 0:
                raise ValueError("env.tcp_obs_box must be 6 numbers (x, y, z [min, max], min < max) and "
                                 f"env.tcp_obs_error > 0, got {list(cfg.tcp_obs_box)}, {cfg.tcp_obs_error}")
            self.tcp_box = box.reshape(3, 2)

        f64 = dict(dtype=torch.float64, device=self.device)
        d = robot.dof
        self.pos = torch.zeros(n, d, **f64)
        self.vel = torch.zeros(n, d, **f64)
        self.acc = torch.zeros(n, d, **f64)
        self.a_min = torch.zeros(n, d, **f64)
        self.a_max = torch.zeros(n, d, **f64)
        self.seg_path = torch.zeros(n, dtype=torch.long, device=self.device)
        self.s = torch.zeros(n, **f64)
        self.knot_i = torch.zeros(n, dtype=torch.long, device=self.device)  # last knot at or behind s
        self.start_s = torch.zeros(n, **f64)
        self.end_s = torch.zeros(n, **f64)
        self.end_knot = torch.zeros(n, dtype=torch.long, device=self.device)
        self.end_q = torch.zeros(n, self.paths.dof, **f64)  # end knot (path joints)
        self.l_obs = torch.zeros(n, **f64)  # arc length of the last knot in the current window
        self.close_to_end = torch.zeros(n, dtype=torch.bool, device=self.device)
        self.braking = torch.zeros(n, dtype=torch.bool, device=self.device)
        self.budget = torch.full((n,), self.max_episode_length, dtype=torch.long, device=self.device)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=self.device)
        self.finish_step = torch.full((n,), -1, dtype=torch.long, device=self.device)
        #: (N,) int8 TerminationReason of the last step (NONE: the episode goes on; pathrl.envs.terminations)
        self.termination = torch.zeros(n, dtype=torch.int8, device=self.device)
        self.ep_reward = {t.name: torch.zeros(n, **f64) for t in reward_terms}
        self.ep_dev_sum = torch.zeros(n, **f64)
        self.ep_dev_max = torch.zeros(n, **f64)
        self.obs_terms, self._obs = active_terms(self), None  # the terms in their order (pathrl.envs.observations)
        self.last_step: dict[str, Tensor] = {}
        #: (N,) bool or None (all): envs whose feedback is simulated. Evaluation rollouts clear the envs whose
        #: episode has ended: their physics would be wasted work (most of an evaluation in PyBullet).
        self.simulated: Tensor | None = None
        #: New episodes start on the first `sample_paths` paths of the bank (None: all); path changes during training
        #: (pathrl.envs.path_changes) keep their branches in rows behind them.
        self.sample_paths: int | None = None
        self.reset()

    @property
    def fk(self) -> ForwardKinematics:
        """The forward kinematics of this env's robot on its device: one object for everything of the env (its
        feedback, TCP observations and rewards, controllers, evaluation metrics), built on first use."""
        if self._fk is None:
            self._fk = ForwardKinematics(self.robot, device=self.device)
        return self._fk

    # ------------------------------------------------------------------ episode management
    def reset(self) -> TensorDict:
        """Reset every env to a fresh training segment."""
        self._reset_envs(torch.arange(self.num_envs, device=self.device))
        return self.get_observations()

    def start_segments(self, env_ids: Tensor, seg: Segments, refresh: bool = True) -> None:
        """Start envs `env_ids` on the given segments (robot at rest at the segment start).

        `refresh=False` defers rebuilding observations (the step rebuilds them once for all envs).
        """
        self.seg_path[env_ids] = seg.path
        self.start_s[env_ids] = seg.start_s
        self.s[env_ids] = seg.start_s
        self.knot_i[env_ids] = self.paths.knot_index_at(seg.path, seg.start_s)
        self.end_s[env_ids] = seg.end_s
        self.end_knot[env_ids] = seg.end_knot
        self.end_q[env_ids] = self.paths.position_at(seg.path, seg.end_s)
        q0 = self.paths.position_at(seg.path, seg.start_s)
        pos = torch.zeros(len(env_ids), self.robot.dof, dtype=torch.float64, device=self.device)
        pos[:, self.path_index] = q0
        self.pos[env_ids] = pos
        self.vel[env_ids] = 0.0
        self.acc[env_ids] = 0.0
        self.braking[env_ids] = False
        self.episode_length_buf[env_ids] = 0
        self.finish_step[env_ids] = -1
        for v in self.ep_reward.values():
            v[env_ids] = 0.0
        if self.feedback is not None:
            self.feedback.reset(env_ids, pos)
        self.ep_dev_sum[env_ids] = 0.0
        self.ep_dev_max[env_ids] = 0.0
        frac = (seg.end_s - seg.start_s) / self.paths.length[seg.path]
        budget_s = self.cfg.episode_budget_s * (frac if self.cfg.scale_budget else torch.ones_like(frac))
        self.budget[env_ids] = torch.round(budget_s / self.cfg.dt).long().clamp(min=1)
        if refresh:
            self._update_window()

    def _reset_envs(self, env_ids: Tensor, refresh: bool = True) -> None:
        if len(env_ids) == 0:
            return
        n_paths = self.paths.num_paths if self.sample_paths is None else self.sample_paths
        idx = torch.randint(n_paths, (len(env_ids),), generator=self.generator, device=self.device)
        if self.cfg.segments == "full":
            seg = full_segments(self.paths, idx)
        else:
            seg = sample_segments(self.paths, idx, self.generator, self.cfg.start_range, self.cfg.min_fraction)
        self.start_segments(env_ids, seg, refresh)

    def replace_path(self, env_ids: Tensor, path: Tensor, s: Tensor, end_knot: Tensor | None = None) -> None:
        """Online path adjustment: envs `env_ids` keep their robot state and now track `path` from arc length `s`.

        The end is the path's last knot unless `end_knot` is given. The new path should pass near the
        robot's current position (the deviation is measured against it from the next step on).
        """
        self.seg_path[env_ids] = path
        self.s[env_ids] = s
        self.knot_i[env_ids] = self.paths.knot_index_at(path, self.s[env_ids])
        self.start_s[env_ids] = s
        ek = self.paths.num_knots[path] - 1 if end_knot is None else end_knot
        self.end_knot[env_ids] = ek
        self.end_s[env_ids] = self.paths.knot_s[path, ek]
        self.end_q[env_ids] = self.paths.position_at(path, self.end_s[env_ids])
        self.braking[env_ids] = False
        self._update_window()

    def _pass_knots(self, look: int = 4) -> None:
        """Move ``knot_i`` past the knots the step's progress reached (s only grows between resets): the
        result equals ``paths.knot_index_at(seg_path, s)`` without searching each env's whole knot row.

        The next `look` knots of every env are compared at once (knot_s is sorted, so the passed ones are a
        prefix); a step rarely passes more, and then the window moves on."""
        width = self.paths.knot_s.shape[1]
        flat, ahead = self.paths.knot_s.reshape(-1), torch.arange(1, look + 1, device=self.device)
        while True:
            nxt = self.knot_i.unsqueeze(1) + ahead  # (N, look)
            exists = nxt < width
            ks = flat.index_select(0, (self.seg_path.unsqueeze(1) * width + nxt.clamp(max=width - 1)).view(-1))
            passed = ((ks.view(nxt.shape) <= self.s.unsqueeze(1)) & exists).sum(dim=1)
            self.knot_i = self.knot_i + passed
            if not bool((passed == look).any()):
                return

    def set_paths(self, paths: PathSet) -> None:
        """Swap the path bank (e.g. an evaluation split). Envs keep running until they are reset."""
        if paths.dof != self.robot.path_dof:
            raise ValueError(f"paths have {paths.dof} joints, robot {self.robot.name} has {self.robot.path_dof} "
                             "path joints")
        paths = paths.to(self.device)
        pos = self.limits.pos[self.path_index]
        excess = table_excess(paths, pos[:, 0], pos[:, 1])
        if bool((excess > INSIDE_TOL).any()):  # an episode starts at rest on its path: it must be inside the range
            raise ValueError(f"{int((excess > INSIDE_TOL).sum())} of {paths.num_paths} paths leave robot "
                             f"{self.robot.name}'s position range (by up to {1e3 * float(excess.max()):.3g} mrad); "
                             "clip them first (pathrl.paths.inside.keep_inside, dataset.out_of_limits=clip)")
        self.paths = paths

    # ------------------------------------------------------------------ observation
    @env_scoped
    def _update_window(self) -> None:
        """Recompute the valid acceleration range, the knot window and the observation of all envs."""
        self.a_min, self.a_max = valid_acceleration_range(self.pos, self.vel, self.acc, self.limits, self.cfg.dt,
                                                          self.limit_backend)
        self._obs = self._observe()

    def _observe(self) -> Tensor:
        """The observation of all envs: the env's terms (:mod:`pathrl.envs.observations`) in their fixed order."""
        state, self.l_obs, self.close_to_end = tracking_state(self)
        return assemble(self.obs_terms, self, {"state": state})

    def observation_layout(self, fields: bool = False) -> list[tuple[str, int, int]]:
        """(term, start, stop) column slices of the observation (``fields``: the state split into its fields)."""
        return observation_layout(self.obs_terms, self, fields)

    @property
    def num_obs(self) -> int:
        """Observation size."""
        return int(self._obs.shape[1])

    def get_observations(self) -> TensorDict:
        """The current observations: ``{"policy": (N, num_obs)}``, with ``critic_obs`` also ``"critic"``
        (:func:`~pathrl.envs.observations.critic_observation`)."""
        groups = {"policy": self._obs}
        if self.cfg.critic_obs:
            groups["critic"] = critic_observation(self)
        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    # ------------------------------------------------------------------ step
    def accelerations(self, actions: Tensor) -> Tensor:
        """Accelerations (N, D) at the end of the next step for `actions` (N, D) (step 1 of the step order).

        With ``free_joint_actions=posture`` the free joints' actions are corrections to a critically damped
        pull back to the start posture (0): a1 = PD(q, v) + action, in the centred action scale.
        """
        if self.cfg.free_joint_actions == "posture":
            w = self.cfg.posture_omega
            pull = acceleration_to_action(-(w * w) * self.pos - (2.0 * w) * self.vel, self.a_min, self.a_max)
            actions = torch.where(self.hold, actions.clamp(-1.0, 1.0) + pull, actions)
        return action_to_acceleration(actions, self.a_min, self.a_max, self.hold)

    @env_scoped  # current() below: this env's limit_backend if it has one
    def step(self, actions: Tensor) -> tuple[TensorDict, Tensor, Tensor, dict]:
        """One decision step of actions (N, D) in [-1, 1] (non-finite entries mapped in); (obs, rewards (N,), dones
        (N,), extras)."""
        cfg = self.cfg
        # a NaN action entry acts as 0 and +-inf as +-1: every action, finite or not, maps into the valid range
        actions = torch.nan_to_num(actions.to(device=self.device, dtype=torch.float64), nan=0.0, posinf=1.0,
                                   neginf=-1.0)
        action_absmax = actions.abs().amax(dim=1)
        a1 = self.accelerations(actions)
        if bool(self.braking.any()):
            brake = braking_within(self.vel, self.acc, self.a_min, self.a_max, cfg.dt, cfg.stop_tolerance)
            a1 = torch.where(self.braking.unsqueeze(1), brake, a1)

        # 2.-4. integrate, progress along the path, deviation (one fused kernel)
        table, length = self.paths.table, self.paths.length
        native_step = (current().native and native.advance_supports(len(self.path_index), cfg.substeps, table.shape[1])
                       and native.applies(self.pos, self.vel, self.acc, a1, self.s, self.end_s, table, length,
                                          self.dev_weights, longs=(self.path_index, self.seg_path)))
        p1, v1, moved, dev_max, dev_mean = (native.advance if native_step else advance)(  # same results (tests)
            self.pos, self.vel, self.acc, a1, self.path_index, self.s, self.end_s, self.seg_path, table, length,
            self.dev_weights, cfg.dt, cfg.substeps, self.paths.table_step)
        moving = moved > 1e-12

        # 5. feedback, reward
        task: dict[str, Tensor] = {}
        failed = torch.zeros_like(moving)
        if self.feedback is not None:
            q_c, v_c, _ = interpolate_step(self.pos, self.vel, self.acc, a1, cfg.dt, self.control_steps)
            fb = self.feedback.step(q_c, v_c, self.simulated)
            task = fb.values
            if fb.failed is not None:
                failed = fb.failed.to(self.device)
        if self.tcp_reward:  # commanded vs reference TCPs at the step's end
            task = {**task, "tcp_dev": tcp_distance(self, p1, torch.minimum(self.s + moved, self.end_s))}
        q = StepQuantities(
            moved=moved,
            l_state=(self.l_obs - self.s).clamp(min=0.0),
            horizon=torch.full_like(moved, self.horizon),
            dev_max=dev_max,
            dev_mean=dev_mean,
            action_absmax=action_absmax,
            close_to_end=self.close_to_end,
            task=task,
        )
        reward = torch.zeros_like(moved)
        for term in self.reward_terms:
            r = term.weight * term(q)
            self.ep_reward[term.name] += r
            reward += r

        # state update
        self.pos, self.vel, self.acc = p1, v1, a1
        self.s = torch.minimum(self.s + moved, self.end_s)
        self._pass_knots()
        self.episode_length_buf += 1
        self.ep_dev_sum += dev_mean
        self.ep_dev_max = torch.maximum(self.ep_dev_max, dev_max)

        # 6. end of path -> braking; stop / deviation -> terminate; budget -> time out
        reached, stopped, dev_term, task_term, terminated, time_outs = self._end_of_step(dev_max, failed)

        # 7. finishing early is worth the rest of the budget
        if cfg.stop_bonus:
            remaining = (self.budget - self.episode_length_buf).clamp(min=0).to(reward.dtype)
            reward = torch.where(stopped, reward * (1.0 + remaining), reward)

        dones = terminated | time_outs
        self.last_step = {
            "moved": moved, "dev_max": dev_max, "dev_mean": dev_mean, "stopped": stopped,
            "dev_terminated": dev_term, "task_failed": task_term, "time_outs": time_outs, "reached": reached,
            "termination": self.termination,
            **{f"task/{k}": v for k, v in task.items()},
        }
        extras = {"time_outs": time_outs, "log": self._episode_log(dones, stopped)}
        if cfg.autoreset:
            self._reset_envs(dones.nonzero().squeeze(1), refresh=False)
        self._update_window()
        return self.get_observations(), reward.to(torch.float32), dones, extras

    def _end_of_step(self, dev_max: Tensor, failed: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor, Tensor]:
        """Step 6 of the step order, after the state update: end of path -> braking; stop / deviation / task
        failure -> terminate; budget -> time out (the terms of :mod:`pathrl.envs.terminations`). Sets
        ``self.termination`` (N,) to each env's reason (a ``TerminationReason``) and returns the (N,) masks
        reached, stopped, dev_term, task_term, terminated, time_outs."""
        cfg = self.cfg
        to_end = None
        if cfg.end_tolerance is not None:  # corner cutting leaves arc length uncovered at the end knot
            to_end = ((self.end_q - self.pos[:, self.path_index]) * self.dev_weights).norm(dim=1)
        reached = terms.end_reached(self.s, self.end_s, to_end, self.knot_gap, cfg.end_tolerance)
        newly = reached & (self.finish_step < 0)
        self.finish_step = torch.where(newly, self.episode_length_buf, self.finish_step)
        stopped = terms.robot_stopped(self.braking, self.vel, self.acc, cfg.stop_tolerance)
        self.braking = self.braking | reached
        dev_term = terms.deviation_exceeded(dev_max, cfg.max_deviation)
        terminated = stopped | dev_term
        task_term = terms.task_failed(failed, cfg.fail_terminates) & ~terminated
        terminated = terminated | task_term
        time_outs = terms.timed_out(self.episode_length_buf, self.budget) & ~terminated
        self.termination = terms.termination_reason(stopped, dev_term, task_term, time_outs)
        return reached, stopped, dev_term, task_term, terminated, time_outs

    def _episode_log(self, dones: Tensor, stopped: Tensor) -> dict:
        """Per-term episode rewards and the share of each termination reason (``self.termination``) over the
        episodes that ended in this step."""
        n_done = int(dones.sum())
        if n_done == 0:
            return {}
        log: dict[str, float | Tensor] = {}
        for name, v in self.ep_reward.items():
            log[f"Episode_Reward/{name}"] = v[dones].mean()
        steps = self.episode_length_buf[dones].to(torch.float64)
        ended = self.termination[dones]
        for reason in terms.ENDINGS:
            if reason is not terms.TerminationReason.TASK_FAILED or self.feedback is not None:
                log[f"Episode_Termination/{reason.label}"] = (ended == reason).float().mean()
        log["Metrics/duration_s"] = (steps * self.cfg.dt)[stopped[dones]].mean() if bool(stopped.any()) else 0.0
        log["Metrics/dev_mean_rad"] = (self.ep_dev_sum[dones] / steps).mean()
        log["Metrics/dev_max_rad"] = self.ep_dev_max[dones].mean()
        return log

    def describe(self) -> dict:
        """JSON-able summary of the env (saved with runs)."""
        return {"cfg": asdict(self.cfg), "robot": self.robot.name, "num_obs": self.num_obs,
                "feedback": None if self.feedback is None else self.feedback.name,
                "num_actions": self.num_actions, "knot_gap_norm": self.knot_gap,
                "obs_layout": [list(s) for s in self.observation_layout()]}
