"""TrueAdapt: online adaptation of a time-parameterised reference trajectory from ball feedback (batched torch).

MDP (TrueAdapt Sec. V; iiwa7 with a ball on a plate, ``task=trueadapt_on_plate | trueadapt_in_place``):
  state   commanded joint position (normalised to [-1, 1] in the position limits), velocity / v_max,
          acceleration / a_max; the measured ball position (current and previous, relative to the usable
          half-size of the plate), in place also the measured offset from the initial ball position
          (/ ``offset_scale``); the next ``n_following`` reference positions (normalised like the position).
          ``obs_*`` switch parts off (the paper's state ablations).
  action  one value in [-1, 1] per joint: the acceleration at the end of the next step in units of a_max,
          CLIPPED into the valid range (eq. 8; :mod:`pathrl.limits.feasible`), interpolated linearly
          within the ``dt`` = 50 ms step. Every limit then holds on the continuous trajectory.
  reward  R = R_T (1 - P_S)(1 - P_D) (:mod:`pathrl.envs.trueadapt_rewards`).
  episode one reference trajectory from its first sample to its last (the adapted trajectory takes exactly
          as long). It starts in the reference's initial state: position p_ref(0), velocity 0, and the
          acceleration of the cubic spline through the samples (:func:`~pathrl.dataset.trueadapt.
          reference_derivatives`; clipped to the acceleration limits), so that
          :meth:`TrueAdaptEnv.reference_actions` replays the reference exactly. It terminates when one joint
          deviates more than ``max_joint_deviation`` from the reference; when the task fails (on plate: the
          ball reaches the border, ``border_margin`` inside the plate edge; in place: it is more than
          ``max_ball_offset`` from its start; both: it leaves the plate) and ``fail_terminates`` is set; and
          at the end of the trajectory. Nothing here is a time-out. Why it ended: ``env.termination``, (N,) int8
          :class:`~pathrl.envs.terminations.TerminationReason` codes set once per step from the pure terms of
          :mod:`pathrl.envs.terminations` (``DEVIATION``, ``TASK_FAILED``, ``TRAJECTORY_END``; first wins).
          A success is an episode that reached the end and never lost the ball.
  ball    the analytic ball (:class:`pathrl.sim.feedback.AnalyticBall`), fed the step's control-rate
          setpoints; domain randomisation per episode: radius, rolling friction (uniform in the configured
          ranges), mass (drawn and kept: the analytic rolling model does not depend on it), and Gaussian
          noise on the measured ball position. With ``task.backend=pybullet`` the PyBullet scene
          (:class:`pathrl.sim.vec.PyBulletBall`) simulates the ball instead and draws radius, mass and
          friction itself (the authors' ranges, :func:`pathrl.sim.ball_plate.sample_ball`); evaluation only.
  critic  with ``critic_obs`` the observation also holds a group ``"critic"`` for an asymmetric critic (PPO only;
          the policy never reads it): the time left in the trajectory / 10 s, the true ball position / usable
          half-size and its velocity over the last step / (1 m/s). Without the time left a value function cannot
          tell a state near the end of a trajectory (little reward to come) from the same state early on.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.dataset.trueadapt import TrajectoryBank
from pathrl.envs import terminations as terms
from pathrl.envs.observations import column_slices
from pathrl.envs.terminations import TerminationReason
from pathrl.envs.trueadapt_rewards import AdaptQuantities, AdaptReward
from pathrl.limits.backend import LimitBackend, env_scoped
from pathrl.limits.feasible import JointLimits, valid_acceleration_range
from pathrl.limits.integrate import end_of_step, interpolate_step
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec
from pathrl.sim.feedback import PLATE_SIZE, AnalyticBall

__all__ = ["MODES", "AdaptEnvCfg", "TrueAdaptEnv", "adapt_cfg_from", "ball_border_position", "ball_lost",
           "build_trueadapt_env", "check_adapt_cfg", "clip_to_range"]

try:  # rsl-rl is a training dependency; the env works without it (evaluation, tests).
    from rsl_rl.env import VecEnv as _VecEnvBase
except ImportError:  # pragma: no cover
    _VecEnvBase = object

MODES = ("on_plate", "in_place")


@dataclass(frozen=True)
class AdaptEnvCfg:
    """Settings: ``num_envs``, ``dt``, ``control_rate`` from ``conf/env``, the rest from ``task.adapt``."""

    num_envs: int = 4096
    device: str = "cpu"
    seed: int = 0
    dt: float = 0.05  # decision step (s); must equal the dataset's sample_dt
    control_rate: float = 240.0  # setpoints per second fed to the ball
    mode: str = "on_plate"  # on_plate | in_place
    n_following: int = 1  # reference positions in the state (0: the ablation without them)
    max_joint_deviation: float = 0.1745  # rad (10 deg): a larger deviation of one joint ends the episode
    border_margin: float = 0.03  # on plate: the border starts this far inside the plate edge (m)
    max_ball_offset: float = 0.06  # in place: the task fails beyond this distance from the start (m)
    offset_scale: float = 0.06  # in place: observed offset (m) that maps to 1
    fail_terminates: bool = True  # task.fail_terminates
    obs_position: bool = True
    obs_velocity: bool = True
    obs_acceleration: bool = True
    obs_ball: bool = True  # task.observe; False: the ball stays at its initial measurement (open loop)
    ball_radius: tuple[float, float] = (0.020, 0.036)  # m, uniform per episode
    rolling_friction: tuple[float, float] = (1e-4, 7e-4)  # m, uniform per episode
    ball_mass: tuple[float, float] = (0.002, 0.203)  # kg, uniform per episode (see module docstring)
    sensor_noise: float = 0.002  # std of the measured ball position per axis (m)
    autoreset: bool = True
    critic_obs: bool = False  # task.adapt.critic_obs: add the privileged group "critic" (module docstring)
    limit_backend: LimitBackend | None = None  # limit code of the steps (pathrl.limits.backend); None: as in effect

    def __post_init__(self) -> None:
        """One-line ValueError naming the key for values that would run but give a wrong result."""
        if self.mode not in MODES:
            raise ValueError(f"task.adapt.mode must be one of {', '.join(MODES)}; got {self.mode!r}")
        for key in ("num_envs",):
            if int(getattr(self, key)) < 1:
                raise ValueError(f"env.{key} must be >= 1, got {getattr(self, key)}")
        if int(self.n_following) < 0:
            raise ValueError(f"task.adapt.n_following must be >= 0, got {self.n_following}")
        for key in ("dt", "control_rate", "max_joint_deviation", "max_ball_offset", "offset_scale"):
            if not float(getattr(self, key)) > 0.0:
                raise ValueError(f"task.adapt.{key} (env.dt, env.control_rate) must be > 0, got {getattr(self, key)}")
        if not 0.0 <= self.border_margin < min(PLATE_SIZE[:2]) / 2 or not self.sensor_noise >= 0.0:
            raise ValueError(f"task.adapt.border_margin must be in [0, plate half-size) and sensor_noise >= 0; got "
                             f"{self.border_margin}, {self.sensor_noise}")
        for key in ("ball_radius", "rolling_friction", "ball_mass"):
            lo, hi = (float(x) for x in getattr(self, key))
            if not 0.0 < lo <= hi:
                raise ValueError(f"task.adapt.{key} must be [lo, hi] with 0 < lo <= hi, got {getattr(self, key)}")
        steps = self.control_rate * self.dt
        if abs(steps - round(steps)) > 1e-9 or round(steps) < 3:
            raise ValueError(f"env.control_rate * env.dt must be an integer >= 3, got {steps}")
        if self.limit_backend is not None and not isinstance(self.limit_backend, LimitBackend):
            raise ValueError(f"env limit_backend must be a LimitBackend or None, got {self.limit_backend!r}")


def clip_to_range(actions: Tensor, acc_limit: Tensor, a_min: Tensor, a_max: Tensor) -> Tensor:
    """Eq. 8: actions (N, D) in [-1, 1] (clamped; NaN -> 0) scaled by a_max (D,) and clipped into [a_min, a_max]."""
    a = torch.nan_to_num(actions.to(a_min.dtype), nan=0.0).clamp(-1.0, 1.0) * acc_limit
    return torch.minimum(torch.maximum(a, a_min), a_max)


def ball_border_position(xy: Tensor, half: Tensor) -> Tensor:
    """max(|x| / h_x, |y| / h_y) for ball centres (N, 2) and the usable half-size (2,): 1 on the border; (N,)."""
    return (xy.abs() / half).amax(dim=1)


def ball_lost(on: Tensor, rel: Tensor, offset: Tensor, mode: str, max_ball_offset: float) -> Tensor:
    """(N,) bool: the task failed -- the ball left the plate (on (N,) bool False), or on plate it reached the
    border (rel (N,) :func:`ball_border_position` >= 1), in place it is more than `max_ball_offset` (m) from its
    start (offset (N,) m)."""
    return ~on | ((rel >= 1.0) if mode == "on_plate" else (offset > max_ball_offset))


class TrueAdaptEnv(_VecEnvBase):
    """N robots adapting reference trajectories while carrying a ball on a plate (rsl-rl ``VecEnv``)."""

    def __init__(self, cfg: AdaptEnvCfg, robot: RobotSpec, bank: TrajectoryBank, reward: AdaptReward,
                 ball: AnalyticBall | None = None, fk: ForwardKinematics | None = None) -> None:
        if abs(bank.dt - cfg.dt) > 1e-12:
            raise ValueError(f"trajectories are sampled every {bank.dt} s, env.dt is {cfg.dt}")
        if bank.pos.shape[2] != robot.dof:
            raise ValueError(f"trajectories have {bank.pos.shape[2]} joints, robot {robot.name} has {robot.dof}")
        self.cfg, self.robot, self.reward = cfg, robot, reward
        self.limit_backend = cfg.limit_backend
        self.device = torch.device(cfg.device)
        self._fk = fk  # the env's one kinematics object (its ball's, controllers', records'), built on first use
        self.num_envs = n = cfg.num_envs
        self.num_actions = robot.dof
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(cfg.seed)
        self.limits = JointLimits.from_robot(robot, device=self.device)
        self.bank = bank.to(self.device)
        self.control_steps = int(round(cfg.control_rate * cfg.dt))
        self.ball = ball if ball is not None else AnalyticBall(robot, n, cfg.control_rate, seed=cfg.seed + 1,
                                                               device=self.device, fk=self.fk)
        self.max_episode_length = int(self.bank.steps.max())
        self.knot_gap = None  # no knots: the runner records this for tracking envs
        f64 = dict(dtype=torch.float64, device=self.device)
        self.half = torch.tensor(PLATE_SIZE[:2], **f64) / 2.0 - cfg.border_margin
        self.pos, self.vel, self.acc = (torch.zeros(n, robot.dof, **f64) for _ in range(3))
        self.a_min, self.a_max = torch.zeros(n, robot.dof, **f64), torch.zeros(n, robot.dof, **f64)
        self.traj = torch.zeros(n, dtype=torch.long, device=self.device)
        self.episode_length_buf = torch.zeros(n, dtype=torch.long, device=self.device)
        self.failed = torch.zeros(n, dtype=torch.bool, device=self.device)
        self.ok_steps = torch.zeros(n, dtype=torch.long, device=self.device)
        #: (N,) int8 TerminationReason of the last step (NONE: the episode goes on; pathrl.envs.terminations)
        self.termination = torch.zeros(n, dtype=torch.int8, device=self.device)
        self.meas, self.prev_meas, self.start_meas, self.start_xy = (torch.zeros(n, 2, **f64) for _ in range(4))
        self.ball_vel = torch.zeros(n, 2, **f64)  # true ball velocity over the last step (m/s), for the critic
        self.ball_mass = torch.zeros(n, **f64)
        self.ep = {k: torch.zeros(n, **f64) for k in ("reward", "acc", "jerk", "offset")}
        self.last_step: dict[str, Tensor] = {}
        #: also keep the step's control-rate setpoints in last_step (tests, logging); off by default: checkpoints
        #: snapshot last_step, and at 4096 envs the setpoints are 8 MB
        self.record_setpoints = False
        #: (N,) bool or None (all): envs whose ball is simulated. Evaluations clear the envs whose episode has ended:
        #: their physics would be wasted work (a third of a PyBullet evaluation's scene steps).
        self.simulated: Tensor | None = None
        self._obs: Tensor | None = None
        self.reset()

    @property
    def fk(self) -> ForwardKinematics:
        """The forward kinematics of this env's robot on its device: one object for the env's ball, controllers
        and records, built on first use."""
        if self._fk is None:
            self._fk = ForwardKinematics(self.robot, device=self.device)
        return self._fk

    # ------------------------------------------------------------------ episodes
    def reset(self) -> TensorDict:
        """Every env starts a random trajectory of the bank."""
        self.start(torch.arange(self.num_envs, device=self.device),
                   torch.randint(self.bank.num, (self.num_envs,), generator=self.generator, device=self.device))
        return self.get_observations()

    def start(self, env_ids: Tensor, traj: Tensor, refresh: bool = True) -> None:
        """Envs `env_ids` start trajectories `traj` (bank indices) in the reference's initial state."""
        if len(env_ids) == 0:
            return
        k = len(env_ids)
        self.traj[env_ids] = traj
        self.pos[env_ids] = self.bank.pos[traj, 0]
        self.vel[env_ids] = 0.0
        self.acc[env_ids] = torch.minimum(torch.maximum(self.bank.acc[traj, 0], -self.limits.acc), self.limits.acc)
        self.episode_length_buf[env_ids] = 0
        self.failed[env_ids] = False
        self.ok_steps[env_ids] = 0
        for v in self.ep.values():
            v[env_ids] = 0.0
        self.ball.reset(env_ids, self.pos[env_ids])
        if isinstance(self.ball, AnalyticBall):  # a PyBullet scene draws its ball in its workers
            self.ball.radius[env_ids] = self._uniform(k, self.cfg.ball_radius)
            self.ball.roll_mu[env_ids] = self._uniform(k, self.cfg.rolling_friction)
        self.ball_mass[env_ids] = self._uniform(k, self.cfg.ball_mass)
        self.start_xy[env_ids] = self.ball.xy[env_ids]
        self.ball_vel[env_ids] = 0.0
        meas = self.ball.xy[env_ids] + self._noise(k)
        self.meas[env_ids], self.prev_meas[env_ids], self.start_meas[env_ids] = meas, meas, meas
        if refresh:
            self._refresh()

    def _uniform(self, k: int, bounds: tuple[float, float]) -> Tensor:
        u = torch.rand(k, generator=self.generator, dtype=torch.float64, device=self.device)
        return bounds[0] + (bounds[1] - bounds[0]) * u

    def _noise(self, k: int) -> Tensor:
        z = torch.randn(k, 2, generator=self.generator, dtype=torch.float64, device=self.device)
        return self.cfg.sensor_noise * z

    # ------------------------------------------------------------------ observation
    @env_scoped
    def _refresh(self) -> None:
        """Valid acceleration range and observation of every env."""
        self.a_min, self.a_max = valid_acceleration_range(self.pos, self.vel, self.acc, self.limits, self.cfg.dt,
                                                          self.limit_backend)
        self._obs = self._observe()

    def reference_at(self, offset: int) -> Tensor:
        """Reference positions (N, D) `offset` samples after the current one (held at the trajectory's end)."""
        i = (self.episode_length_buf + offset).clamp(max=self.bank.steps[self.traj])
        return self.bank.pos[self.traj, i]

    def _obs_parts(self) -> list[tuple[str, Tensor]]:
        """The state's parts in order (module docstring), as (name, (N, k) float64 before clipping)."""
        cfg, lim = self.cfg, self.limits
        lo, hi = lim.pos[:, 0], lim.pos[:, 1]

        def norm(p: Tensor) -> Tensor:
            return 2.0 * (p - lo) / (hi - lo) - 1.0

        parts = []
        if cfg.obs_position:
            parts.append(("pos", norm(self.pos)))
        if cfg.obs_velocity:
            parts.append(("vel", self.vel / lim.vel))
        if cfg.obs_acceleration:
            parts.append(("acc", self.acc / lim.acc))
        parts += [("prev_ball", self.prev_meas / self.half), ("ball", self.meas / self.half)]
        if cfg.mode == "in_place":
            parts.append(("ball_offset", (self.meas - self.start_meas) / cfg.offset_scale))
        parts += [(f"reference_{k}", norm(self.reference_at(k))) for k in range(1, cfg.n_following + 1)]
        return parts

    def _observe(self) -> Tensor:
        return torch.cat([t for _, t in self._obs_parts()], dim=1).clamp(-1.0, 1.0).to(torch.float32)

    def observation_layout(self) -> list[tuple[str, int, int]]:
        """(part, start, stop) column slices of the observation, in order; they cover it exactly."""
        return column_slices([(name, int(t.shape[1])) for name, t in self._obs_parts()])

    @property
    def num_obs(self) -> int:
        """Observation size."""
        return int(self._obs.shape[1])

    def critic_observation(self) -> Tensor:
        """The privileged part of the critic's state (N, 5) float32: time left (s) / 10, true ball position / usable
        half-size (2), its velocity over the last step (2, m/s)."""
        left = (self.bank.steps[self.traj] - self.episode_length_buf).to(torch.float64) * self.cfg.dt / 10.0
        return torch.cat([left[:, None], self.ball.xy / self.half, self.ball_vel], dim=1).to(torch.float32)

    def get_observations(self) -> TensorDict:
        """The current observations: ``{"policy": (N, num_obs)}``, with ``critic_obs`` also ``"critic"`` (N, 5)."""
        groups = {"policy": self._obs}
        if self.cfg.critic_obs:
            groups["critic"] = self.critic_observation()
        return TensorDict(groups, batch_size=[self.num_envs], device=self.device)

    def ball_on(self) -> Tensor:
        """(N,) bool: the ball is still on the plate (analytic model: ``on``; PyBullet scene: ``ok``)."""
        return self.ball.on if isinstance(self.ball, AnalyticBall) else self.ball.ok

    def close(self) -> None:
        """Release the ball's simulator processes (PyBullet; nothing for the analytic model)."""
        self.ball.close()

    def reference_actions(self) -> Tensor:
        """Actions (N, D) that replay the reference (its spline accelerations at the next sample / a_max)."""
        i = (self.episode_length_buf + 1).clamp(max=self.bank.steps[self.traj])
        return (self.bank.acc[self.traj, i] / self.limits.acc).clamp(-1.0, 1.0)

    # ------------------------------------------------------------------ step
    @env_scoped
    def step(self, actions: Tensor) -> tuple[TensorDict, Tensor, Tensor, dict]:
        """One decision step of actions (N, D) in [-1, 1] (Eq. 8: scaled, clipped into the valid acceleration range);
        (obs, rewards (N,), dones (N,), extras)."""
        cfg, lim = self.cfg, self.limits
        a1 = clip_to_range(actions.to(self.device), lim.acc, self.a_min, self.a_max)
        q_c, v_c, a_c = interpolate_step(self.pos, self.vel, self.acc, a1, cfg.dt, self.control_steps)
        p1, v1 = end_of_step(self.pos, self.vel, self.acc, a1, cfg.dt)
        prev_xy = self.ball.xy.clone()
        self.ball.step(q_c, v_c, self.simulated)
        ref1 = self.reference_at(1)
        xy = self.ball.xy
        self.ball_vel = (xy - prev_xy) / cfg.dt
        rel = ball_border_position(xy, self.half)
        offset = (xy - self.start_xy).norm(dim=1)
        lost = ball_lost(self.ball_on(), rel, offset, cfg.mode, cfg.max_ball_offset)
        self.failed |= lost
        q = AdaptQuantities(acc_norm=a1.abs() / lim.acc, jerk=(a1 - self.acc).abs() / cfg.dt, jerk_max=lim.jerk,
                            deviation=(p1 - ref1).abs().amax(dim=1), ball_rel=rel, ball_offset=offset,
                            ball_ok=(~self.failed).to(torch.float64))
        reward_terms = self.reward.terms(q)
        reward = self.reward.combine(reward_terms)

        self.pos, self.vel, self.acc = p1, v1, a1
        self.episode_length_buf += 1
        self.ok_steps += (~self.failed).long()
        self.prev_meas = self.meas
        if cfg.obs_ball:
            self.meas = xy + self._noise(self.num_envs)
        self.ep["reward"] += reward
        self.ep["acc"] += q.acc_norm.mean(dim=1)
        self.ep["jerk"] += (q.jerk / lim.jerk).mean(dim=1)
        self.ep["offset"] += offset

        self.termination = self._termination(q.deviation, lost)
        dones = self.termination != TerminationReason.NONE
        success = (self.termination == TerminationReason.TRAJECTORY_END) & ~self.failed
        self.last_step = {"a1": a1, "deviation": q.deviation, "ball_xy": xy, "ball_offset": offset,
                          "failed": self.failed.clone(), "success": success, "termination": self.termination,
                          "dones": dones, **{f"term/{k}": v for k, v in reward_terms.items()}}
        if self.record_setpoints:
            self.last_step.update(q_control=q_c, v_control=v_c, a_control=a_c)
        extras = {"time_outs": torch.zeros_like(dones), "log": self._episode_log(dones, success)}
        if cfg.autoreset:
            ids = dones.nonzero().squeeze(1)
            self.start(ids, torch.randint(self.bank.num, (len(ids),), generator=self.generator, device=self.device),
                       refresh=False)
        self._refresh()
        return self.get_observations(), reward.to(torch.float32), dones, extras

    def _termination(self, deviation: Tensor, lost: Tensor) -> Tensor:
        """(N,) int8 reasons of this step (after the state update) from the terms of :mod:`pathrl.envs.terminations`:
        a joint's deviation (N,) rad beyond ``max_joint_deviation``, the task failed in this step (lost (N,) bool)
        with ``fail_terminates``, the trajectory's last sample reached; the first wins (``ADAPT_ENDINGS``)."""
        masks = (terms.deviation_exceeded(deviation, self.cfg.max_joint_deviation),
                 terms.task_failed(lost, self.cfg.fail_terminates),
                 terms.timed_out(self.episode_length_buf, self.bank.steps[self.traj]))
        return terms.first_reason(list(zip(terms.ADAPT_ENDINGS, masks, strict=True)))

    def episode_metrics(self, dones: Tensor) -> dict[str, Tensor]:
        """Per finished env (dones (N,) bool; call before the reset): trajectory fraction executed before the task
        failed, mean normalised |a| and |jerk|, mean ball offset from its start (m); all (n_done,)."""
        steps = self.episode_length_buf[dones].clamp(min=1).to(torch.float64)
        total = self.bank.steps[self.traj[dones]].to(torch.float64)
        return {"fraction": self.ok_steps[dones] / total, "acc": self.ep["acc"][dones] / steps,
                "jerk": self.ep["jerk"][dones] / steps, "offset": self.ep["offset"][dones] / steps}

    def _episode_log(self, dones: Tensor, success: Tensor) -> dict:
        """Episode reward, the share of each termination reason (``self.termination``) and the metrics of the
        episodes that ended in this step."""
        if not bool(dones.any()):
            return {}
        m = self.episode_metrics(dones)
        ended = self.termination[dones]
        return {"Episode_Reward/total": self.ep["reward"][dones].mean(),
                **{f"Episode_Termination/{r.label}": (ended == r).float().mean() for r in terms.ADAPT_ENDINGS},
                "Metrics/success": success[dones].float().mean(), "Metrics/trajectory_fraction": m["fraction"].mean(),
                "Metrics/acc_norm": m["acc"].mean(), "Metrics/jerk_norm": m["jerk"].mean(),
                "Metrics/ball_offset_m": m["offset"].mean()}

    def describe(self) -> dict:
        """JSON-able summary of the env (saved with runs)."""
        return {"cfg": asdict(self.cfg), "robot": self.robot.name, "num_obs": self.num_obs,
                "num_actions": self.num_actions, "trajectories": self.bank.num,
                "obs_layout": [list(s) for s in self.observation_layout()]}


# ---------------------------------------------------------------------------------------------------- config glue
def adapt_cfg_from(cfg: dict, num_envs: int | None = None, seed: int | None = None) -> AdaptEnvCfg:
    """The env settings of a resolved run config: ``env.num_envs / dt / control_rate`` and ``task.adapt``."""
    from dataclasses import fields

    adapt = dict(cfg["task"]["adapt"])
    known = {f.name for f in fields(AdaptEnvCfg)} - {"num_envs", "device", "seed", "dt", "control_rate",
                                                    "fail_terminates", "obs_ball", "autoreset", "limit_backend"}
    unknown = sorted(set(adapt) - known)
    if unknown:
        raise ValueError(f"task.adapt: unknown keys {unknown}; valid: {sorted(known)}")
    for key in ("ball_radius", "rolling_friction", "ball_mass"):
        if key in adapt:
            adapt[key] = tuple(float(x) for x in adapt[key])
    e = cfg["env"]
    return AdaptEnvCfg(num_envs=int(num_envs or e["num_envs"]), device=str(cfg.get("device", "cpu")),
                       seed=int(cfg.get("seed", 0) if seed is None else seed), dt=float(e["dt"]),
                       control_rate=float(e["control_rate"]), fail_terminates=bool(cfg["task"]["fail_terminates"]),
                       obs_ball=bool(cfg["task"]["observe"]), **adapt)


def check_adapt_cfg(cfg: dict) -> None:
    """Refuse a bad TrueAdapt config before any work (one-line ValueError)."""
    from pathrl.envs.trueadapt_rewards import build_adapt_reward

    env_cfg = adapt_cfg_from(cfg)
    reward = build_adapt_reward(cfg["reward"]["terms"])
    if reward.task != env_cfg.mode:
        raise ValueError(f"reward.terms: task term {reward.task!r} does not match task.adapt.mode {env_cfg.mode!r}")
    if cfg["task"].get("feedback") != "ball_on_plate" or cfg["task"].get("backend") not in ("analytic", "pybullet"):
        raise ValueError("task: TrueAdapt needs feedback ball_on_plate with backend analytic or pybullet")


def build_trueadapt_env(cfg: dict, split: str = "train", num_envs: int | None = None, dataset_path: str | None = None,
                        seed: int | None = None, **overrides) -> TrueAdaptEnv:
    """The TrueAdapt env of a resolved config on a dataset split (built through pathrl.envs.registry.make_env);
    `overrides` replace AdaptEnvCfg fields (evaluation: ``autoreset=False``, open loop: ``obs_ball=False``)."""
    from dataclasses import replace

    from pathrl.dataset.trueadapt import load_trajectories
    from pathrl.envs.device import check_run_device
    from pathrl.envs.trueadapt_rewards import build_adapt_reward
    from pathrl.robot.model import load_robot

    check_adapt_cfg(cfg)
    env_cfg = replace(adapt_cfg_from(cfg, num_envs, seed), **overrides)
    check_run_device({"device": env_cfg.device, "task": cfg["task"]})  # before any data is read; PyBullet: the CPU
    robot = load_robot(cfg["robot"])
    bank = load_trajectories(dataset_path or cfg["dataset"]["path"], split, robot, env_cfg.dt)
    fk = ForwardKinematics(robot, device=env_cfg.device)  # the env's, shared with its ball
    ball = None
    if cfg["task"]["backend"] == "pybullet":
        from pathrl.sim.vec import PyBulletBall

        ball = PyBulletBall(robot, env_cfg.num_envs, env_cfg.control_rate, seed=env_cfg.seed + 1,
                            workers=int(cfg["task"].get("workers", 2)), fk=fk)
    return TrueAdaptEnv(env_cfg, robot, bank, build_adapt_reward(cfg["reward"]["terms"]), ball, fk)
