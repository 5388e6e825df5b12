"""Sensory feedback of a physical task (ball on plate, ...) for the path-tracking env.

A feedback source sees the control-rate joint setpoints of every decision step and returns what a sensor
would report (observation), the per-env quantities its reward terms need, and whether the task failed
(ball off the plate). Two kinds of sources implement the same :class:`Feedback` interface:

* analytic torch models (:class:`AnalyticBall`): batched over all envs, fast enough for training;
* PyBullet scenes in worker processes (:mod:`pathrl.sim.vec`): the reference, used for evaluation.

The env never imports PyBullet: it only calls this interface.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import torch
from torch import Tensor

from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec

__all__ = ["BALL_RADIUS_MM", "GRAVITY", "PLACE_MARGIN", "PLATE_BORDER", "PLATE_SIZE", "RES_FACTOR", "ROLL_FACTOR",
           "ROLL_MU_1E4", "USABLE_HALF", "AnalyticBall", "Feedback", "FeedbackStep", "FrozenSensor", "PlateDrive",
           "PlateIMU", "ball_observation", "ball_reach", "ball_values", "inplane_force", "mean_drive", "plate_pose",
           "rolling_resistance", "sample_ball_radius", "sample_ball_xy", "sample_rolling_friction"]


GRAVITY = 9.81  # m/s^2

# Plate and ball geometry (the authors' values, original_pathtracking.md 8.1); shared with pathrl.sim.ball_plate.
PLATE_SIZE = (0.3393, 0.2715, 0.002)  # logical plate size (m)
PLATE_BORDER = 0.03  # usable area ends this far inside the edge (m)
PLACE_MARGIN = 0.06  # initial ball position keeps this far inside the usable area (m)
USABLE_HALF = (PLATE_SIZE[0] / 2 - PLATE_BORDER, PLATE_SIZE[1] / 2 - PLATE_BORDER)  # (0.13965, 0.10575)
BALL_RADIUS_MM = (20, 36)  # integer mm, inclusive
ROLL_MU_1E4 = (1, 7)  # rolling friction x 1e4, integer, inclusive
ROLL_FACTOR = 5.0 / 7.0  # in-plane ball acceleration / in-plane (g - a_plate): solid sphere rolling without slip
# Rolling friction mu (m) resists like a force RES_FACTOR * mu * N / radius (fitted to PyBullet on tilted plates:
# 1-10 deg, mu 1e-4..7e-4, radius 20-36 mm; tests/test_feedback.py)
RES_FACTOR = 0.5


def ball_reach(rel: Tensor) -> Tensor:
    """The authors' signed ball offset (N,) of balls at `rel` (N, 2), plate axes, relative to the usable half-sizes.

    Their board is turned by -90 deg about the TCP's z axis (board x = TCP -y, board y = TCP +x; ours is not
    turned) and their reward reads max(x_board, y_board): only offsets toward the board's +x / +y count. Returns
    max(-rel_y, rel_x), each relative to this plate's usable half-size along that axis.
    """
    return torch.maximum(-rel[:, 1], rel[:, 0])


def ball_values(rel: Tensor, on: Tensor, drive: Tensor) -> dict[str, Tensor]:
    """Task values (N,) of balls at `rel` (N, 2) (relative to the usable half-sizes), on the plate `on` (N,) bool,
    plate drive `drive` (N,): ball_dist (distance from the centre), ball_reach (:func:`ball_reach`), ball_on_plate
    (1 / 0), ball_drive."""
    return {"ball_dist": rel.norm(dim=1), "ball_reach": ball_reach(rel), "ball_on_plate": on.to(torch.float64),
            "ball_drive": drive}


@dataclass(frozen=True)
class FeedbackStep:
    """One decision step of a feedback source, per env.

    obs: (N, k) sensor observation in about [-1, 1].
    values: named (N,) quantities for reward terms and metrics (e.g. ``ball_dist``).
    failed: (N,) the task failed during this step (e.g. the ball left the plate).
    """

    obs: Tensor
    values: dict[str, Tensor] = field(default_factory=dict)
    failed: Tensor | None = None


class Feedback(Protocol):
    """What the env needs from a feedback source (all tensors (N, ...), float64 setpoints)."""

    name: str
    num_obs: int
    value_names: tuple[str, ...]  # keys of FeedbackStep.values
    ok_value: str  # the value that is 1 while the task has not failed (sticky)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Envs `env_ids` start a new episode with the robot at rest at `q` (len(env_ids), D)."""

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """Advance every env through one decision step of setpoints `q`, `qd` (N, C, D) at the control rate.

        `active` (N,) bool: only these envs need simulating (the others' episodes are over; their values
        may be stale). A source may simulate more (the batched torch model simulates all)."""

    def observe(self) -> Tensor:
        """Current observation (N, num_obs)."""

    def close(self) -> None:
        """Release processes / clients (no-op for torch models)."""


def ball_observation(prev_rel: Tensor, rel: Tensor, imu: PlateIMU | None = None) -> Tensor:
    """The authors' ball state: previous then current (x, y) relative to the usable half-size; (N, 4).

    With a plate `imu` its reading follows; (N, 8)."""
    parts = [prev_rel, rel] + ([imu.reading.to(rel.device)] if imu is not None else [])
    return torch.cat(parts, dim=1)


def plate_pose(fk: ForwardKinematics, q: Tensor) -> tuple[Tensor, Tensor]:
    """Plate centre (surface mid-plane) positions (..., 3) and rotations (..., 3, 3) for setpoints (..., D)."""
    shape = q.shape[:-1]
    pos, rot = fk.tcp_transforms(q.reshape(-1, q.shape[-1]))
    pos = pos[:, 0] + rot[:, 0, :, 2] * (PLATE_SIZE[2] / 2)  # the plate's centre sits half its thickness up
    return pos.reshape(*shape, 3), rot[:, 0].reshape(*shape, 3, 3)


def inplane_force(o: Tensor, r: Tensor, h: float) -> Tensor:
    """In-plane specific force ``R^T (g - a)`` (x, y; units of g) of plate poses ``o`` (N, T, 3), ``r``
    (N, T, 3, 3) sampled ``h`` seconds apart, at the interior instants 1..T-2 (central second differences
    of ``o``); (N, T-2, 2). A ball rolling on the plate accelerates relative to it by 5/7 of this (x g)."""
    acc = (o[:, 2:] - 2.0 * o[:, 1:-1] + o[:, :-2]) / h**2
    g = torch.tensor([0.0, 0.0, -GRAVITY], dtype=o.dtype, device=o.device)
    return ((g - acc).unsqueeze(-2) @ r[:, 1:-1]).squeeze(-2)[..., :2] / GRAVITY


class PlateDrive:
    """What pushes a ball around on the plate during a decision step: the mean magnitude of the plate's
    in-plane specific force (:func:`inplane_force`, units of g), (N,).

    Zero while the plate is held level at rest, and while it is tilted into its acceleration the way a
    waiter tilts a tray (``tan(tilt) = a / g``); a ball then keeps its place on the plate. Sampled at
    ``model_rate`` (every ``stride``-th setpoint, the analytic ball model's rate) with the last two
    instants of the previous step as history, from forward kinematics of the commanded setpoints (the
    same in both backends). The reward term ``ball_drive`` reads it.
    """

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, model_rate: float = 40.0,
                 device: str | torch.device = "cpu", fk: ForwardKinematics | None = None):
        self.device = torch.device(device)
        self.fk = fk if fk is not None else ForwardKinematics(robot, device=self.device)
        self.stride = max(1, int(round(control_rate / model_rate)))
        self.h = self.stride / control_rate
        f64 = dict(dtype=torch.float64, device=self.device)
        self.hist_o = torch.zeros(num_envs, 2, 3, **f64)
        self.hist_r = torch.eye(3, **f64).expand(num_envs, 2, 3, 3).clone()
        self.value = torch.zeros(num_envs, **f64)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Envs `env_ids` at rest at `q` (len(env_ids), D)."""
        if len(env_ids) == 0:
            return
        o, r = plate_pose(self.fk, q)
        self.hist_o[env_ids] = o.unsqueeze(1).expand(len(env_ids), 2, 3)
        self.hist_r[env_ids] = r.unsqueeze(1).expand(len(env_ids), 2, 3, 3)
        self.value[env_ids] = 0.0

    def step(self, q: Tensor) -> Tensor:
        """The drive during a step of setpoints `q` (N, C, D); returns it (N,)."""
        o, r = plate_pose(self.fk, q[:, self.stride - 1 :: self.stride])
        o, r = torch.cat([self.hist_o, o], dim=1), torch.cat([self.hist_r, r], dim=1)
        self.hist_o, self.hist_r = o[:, -2:].clone(), r[:, -2:].clone()
        self.value = mean_drive(o, r, self.h)
        return self.value


def mean_drive(o: Tensor, r: Tensor, h: float) -> Tensor:
    """Mean magnitude of :func:`inplane_force` over the interior instants; (N,) in g."""
    return inplane_force(o, r, h).norm(dim=-1).mean(dim=1)


class PlateIMU:
    """An inertial sensor on the plate, read from the control-rate setpoints (both backends read it alike).

    Reading at the end of a decision step, (N, 4), in units of g: the in-plane specific force
    ``R^T (g - a)`` (x, y: what drives a ball rolling on the plate, 7/5 of its acceleration relative to
    the plate) at the step's last-but-one setpoint (central second difference of the last three plate
    centres, 1/control_rate apart), then the in-plane gravity ``R^T g`` (x, y: the plate's tilt) at the
    last setpoint. A level plate at rest reads 0. An accelerometer and an attitude estimate on the plate
    would report the same; here they follow from forward kinematics of the commanded setpoints, the
    way the authors computed the Cartesian state.
    """

    num_obs = 4

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0,
                 device: str | torch.device = "cpu", fk: ForwardKinematics | None = None):
        self.device = torch.device(device)
        self.fk = fk if fk is not None else ForwardKinematics(robot, device=self.device)
        self.h = 1.0 / control_rate
        self.reading = torch.zeros(num_envs, 4, dtype=torch.float64, device=self.device)
        self.g = torch.tensor([0.0, 0.0, -GRAVITY], dtype=torch.float64, device=self.device)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Envs `env_ids` at rest at `q` (len(env_ids), D): specific force = gravity."""
        if len(env_ids) == 0:
            return
        _, rot = plate_pose(self.fk, q)
        grav = (self.g.expand(len(env_ids), 3).unsqueeze(1) @ rot).squeeze(1)[:, :2] / GRAVITY
        self.reading[env_ids] = torch.cat([grav, grav], dim=1)

    def step(self, q: Tensor) -> Tensor:
        """Read the sensor after a step of setpoints `q` (N, C >= 3, D); returns the reading (N, 4)."""
        o, rot = plate_pose(self.fk, q[:, -3:])
        force = inplane_force(o, rot, self.h)[:, 0]
        grav = (self.g.expand(len(q), 3).unsqueeze(1) @ rot[:, 2]).squeeze(1)[:, :2] / GRAVITY
        self.reading = torch.cat([force, grav], dim=1)
        return self.reading


def sample_ball_radius(n: int, generator: torch.Generator, device: torch.device) -> Tensor:
    """Ball radii (n,) in metres, integer millimetres uniform in BALL_RADIUS_MM (the authors' randomization)."""
    lo, hi = BALL_RADIUS_MM
    return torch.randint(lo, hi + 1, (n,), generator=generator, device=device).to(torch.float64) / 1000.0


def sample_rolling_friction(n: int, generator: torch.Generator, device: torch.device) -> Tensor:
    """Rolling friction coefficients (n,), k / 10000 with integer k uniform in ROLL_MU_1E4 (the authors' range)."""
    lo, hi = ROLL_MU_1E4
    return torch.randint(lo, hi + 1, (n,), generator=generator, device=device).to(torch.float64) / 10000.0


def sample_ball_xy(n: int, generator: torch.Generator, device: torch.device) -> Tensor:
    """Initial ball centres (n, 2) on the plate (m), uniform inside the placement area."""
    half = torch.tensor([USABLE_HALF[0] - PLACE_MARGIN, USABLE_HALF[1] - PLACE_MARGIN], dtype=torch.float64,
                        device=device)
    return (torch.rand(n, 2, generator=generator, dtype=torch.float64, device=device) * 2.0 - 1.0) * half


class AnalyticBall:
    """Solid ball rolling without slipping on the plate at the TCP, batched in torch.

    Per control period, with the plate pose (O, R) from forward kinematics of the setpoints, the plate
    point under the ball p = O + R r (r = ball centre in plate coordinates) is differenced twice in time to
    get its acceleration a_p (this includes alpha x r and omega x (omega x r)). No slip at the contact and
    the ball's angular momentum give, for a plate turning at w_n about its normal, the acceleration
    relative to the plate (plate coordinates, in-plane)

        r'' = f (g - a_p) - (1 + f) w_n x r',    f = m rho^2 / (I + m rho^2)

    (f = 5/7 for a solid sphere). The second term makes a ball on a turning plate circle instead of
    drifting outward. Rolling friction (coefficient mu 1e-4..7e-4 m, drawn per episode as the authors did)
    acts as a Coulomb-like resistance of f RES_FACTOR mu |g_n| / radius: a resting ball stays put under
    small plate accelerations (for a 20 mm ball with mu 7e-4 up to 0.12 m/s^2), which is much of what
    keeps a ball on a slowly moving plate. Neglected: the tilting components of the plate's angular
    velocity, contact compliance and bouncing. The ball leaves the plate when its centre passes the plate
    edge; it then stays off. The model steps at ``model_rate`` (default 40 Hz: every sixth 240 Hz setpoint;
    forward kinematics dominates its cost). Validated against PyBullet in tests/test_feedback.py.
    """

    name = "ball_on_plate"
    num_obs = 4
    value_names = ("ball_dist", "ball_reach", "ball_on_plate", "ball_drive")
    ok_value = "ball_on_plate"

    def __init__(self, robot: RobotSpec, num_envs: int, control_rate: float = 240.0, seed: int = 0,
                 device: str | torch.device = "cpu", model_rate: float = 40.0, imu: bool = False,
                 fk: ForwardKinematics | None = None):
        if len(robot.tcps) != 1:
            raise ValueError(f"ball on plate needs a robot with one TCP, {robot.name} has {len(robot.tcps)}")
        self.device = torch.device(device)
        self.fk = fk if fk is not None else ForwardKinematics(robot, device=self.device)  # the env's (make_env)
        self.imu = PlateIMU(robot, num_envs, control_rate, self.device, self.fk) if imu else None
        self.num_obs = 4 + (PlateIMU.num_obs if imu else 0)
        self.n = num_envs
        self.stride = max(1, int(round(control_rate / model_rate)))  # every stride-th setpoint drives the model
        self.dtc = self.stride / control_rate
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(seed)
        f64 = dict(dtype=torch.float64, device=self.device)
        self.xy = torch.zeros(num_envs, 2, **f64)
        self.vxy = torch.zeros(num_envs, 2, **f64)
        self.radius = torch.full((num_envs,), 0.0275, **f64)
        self.roll_mu = torch.full((num_envs,), 3e-4, **f64)  # rolling friction coefficient (m)
        self.on = torch.ones(num_envs, dtype=torch.bool, device=self.device)
        self.prev_rel = torch.zeros(num_envs, 2, **f64)
        self.drive = torch.zeros(num_envs, **f64)  # PlateDrive's value, from this model's plate poses
        self.hist_o = torch.zeros(num_envs, 2, 3, **f64)  # plate origin at the last two control instants
        self.hist_r = torch.eye(3, **f64).expand(num_envs, 2, 3, 3).clone()
        self.half = torch.tensor(USABLE_HALF, **f64)
        self.edge = torch.tensor(PLATE_SIZE[:2], **f64) / 2.0
        self.g = torch.tensor([0.0, 0.0, -GRAVITY], **f64)

    #: Curriculum scales of new balls (:meth:`set_curriculum`): rolling friction x roll_scale, start x start_spread.
    roll_scale: float = 1.0
    start_spread: float = 1.0

    def set_curriculum(self, roll_scale: float, start_spread: float) -> None:
        """Balls drawn from now on: rolling friction times `roll_scale` (>= 1), start position times `start_spread`
        (in [0, 1]; 0 is the plate's centre). (1, 1) is the authors' randomization."""
        if roll_scale < 1.0 or not 0.0 <= start_spread <= 1.0:
            raise ValueError(f"ball curriculum: roll_scale >= 1 and start_spread in [0, 1], got {roll_scale}, "
                             f"{start_spread}")
        self.roll_scale, self.start_spread = float(roll_scale), float(start_spread)

    def plate_pose(self, q: Tensor) -> tuple[Tensor, Tensor]:
        """:func:`plate_pose` of this model's robot."""
        return plate_pose(self.fk, q)

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """See :meth:`Feedback.reset`: a new ball (position, radius, rolling friction) at rest on the plate of envs
        `env_ids`."""
        if len(env_ids) == 0:
            return
        k = len(env_ids)
        self.xy[env_ids] = sample_ball_xy(k, self.generator, self.device) * self.start_spread
        self.vxy[env_ids] = 0.0
        self.radius[env_ids] = sample_ball_radius(k, self.generator, self.device)
        self.roll_mu[env_ids] = sample_rolling_friction(k, self.generator, self.device) * self.roll_scale
        self.on[env_ids] = True
        o, r = self.plate_pose(q)
        self.hist_o[env_ids] = o.unsqueeze(1).expand(k, 2, 3)
        self.hist_r[env_ids] = r.unsqueeze(1).expand(k, 2, 3, 3)
        self.prev_rel[env_ids] = self.xy[env_ids] / self.half
        self.drive[env_ids] = 0.0
        if self.imu is not None:
            self.imu.reset(env_ids, q)

    def _point(self, o: Tensor, r: Tensor, local: Tensor) -> Tensor:
        return o + (r @ local.unsqueeze(-1)).squeeze(-1)

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """See :meth:`Feedback.step`: roll the balls through the decision step's setpoints (N, C, D)."""
        if self.imu is not None:
            self.imu.step(q)
        q = q[:, self.stride - 1 :: self.stride]
        c = q.shape[1]
        o, r = self.plate_pose(q)  # (N, C, 3), (N, C, 3, 3)
        o = torch.cat([self.hist_o, o], dim=1)  # instants -2, -1, 0 .. C-1 -> index k + 2
        r = torch.cat([self.hist_r, r], dim=1)
        self.prev_rel = self.xy / self.half
        self.drive = mean_drive(o, r, self.dtc)
        was_on = self.on.clone()
        for k in range(c):
            # acceleration of the plate point under the ball at instant k-1 (central difference)
            local = torch.cat([self.xy, self.radius.unsqueeze(1) + PLATE_SIZE[2] / 2], dim=1)
            p0 = self._point(o[:, k], r[:, k], local)
            p1 = self._point(o[:, k + 1], r[:, k + 1], local)
            p2 = self._point(o[:, k + 2], r[:, k + 2], local)
            a_p = (p2 - 2.0 * p1 + p0) / self.dtc**2
            rel_g = ((self.g - a_p).unsqueeze(1) @ r[:, k + 1]).squeeze(1)  # R^T (g - a_p), plate frame
            # plate angular velocity about its normal: skew(w) = dR/dt R^T, expressed in the plate frame
            w = ((r[:, k + 2] - r[:, k]) / (2.0 * self.dtc)) @ r[:, k + 1].transpose(1, 2)
            w_z = (r[:, k + 1, :, 2] * torch.stack([w[:, 2, 1] - w[:, 1, 2], w[:, 0, 2] - w[:, 2, 0],
                                                    w[:, 1, 0] - w[:, 0, 1]], dim=1)).sum(1) / 2.0
            f = ROLL_FACTOR
            spin = (1.0 + f) * w_z.unsqueeze(1) * torch.stack([self.vxy[:, 1], -self.vxy[:, 0]], dim=1)  # -(1+f) w x v
            drive = f * rel_g[:, :2] + spin
            a_res = f * RES_FACTOR * self.roll_mu * rel_g[:, 2].abs() / self.radius
            self.vxy = rolling_resistance(self.vxy, drive, a_res, self.dtc) * self.on.unsqueeze(1)
            self.xy = self.xy + self.vxy * self.dtc * self.on.unsqueeze(1)
            self.on = self.on & (self.xy.abs() <= self.edge).all(dim=1) & (rel_g[:, 2] < 0.0)
        self.hist_o = o[:, -2:].clone()
        self.hist_r = r[:, -2:].clone()
        return FeedbackStep(obs=self.observe(), values=self.values(), failed=was_on & ~self.on)

    def values(self) -> dict[str, Tensor]:
        """Task values per env (N,) for reward terms (:func:`ball_values`)."""
        return ball_values(self.xy / self.half, self.on, self.drive)

    def observe(self) -> Tensor:
        """See :meth:`Feedback.observe`: the ball state (N, 4), clamped to [-1, 1]."""
        return ball_observation(self.prev_rel, self.xy / self.half, self.imu).clamp(-1.0, 1.0)

    def privileged(self) -> Tensor:
        """What an asymmetric critic may see and the policy does not (N, 4) float64: the ball's velocity on the
        plate (m/s, 2), its radius / 30 mm and its rolling friction coefficient / 1 mm (drawn per episode)."""
        return torch.cat([self.vxy, (self.radius / 0.03)[:, None], (self.roll_mu / 1e-3)[:, None]], dim=1)

    def close(self) -> None:
        """Nothing to release (torch model)."""
        pass


def rolling_resistance(v: Tensor, drive: Tensor, a_res: Tensor, dt: float) -> Tensor:
    """Velocity (N, 2) after one step of `drive` (N, 2) acceleration against a Coulomb-like rolling resistance
    of magnitude `a_res` (N,): a resting ball stays put while |drive| <= a_res, a rolling one is decelerated
    along its velocity and stops instead of reversing."""
    a_res = a_res.unsqueeze(1)
    speed = v.norm(dim=1, keepdim=True)
    resting = speed < 1e-9
    d_norm = drive.norm(dim=1, keepdim=True)
    start = torch.where(d_norm > a_res, drive * (1.0 - a_res / d_norm.clamp(min=1e-12)), torch.zeros_like(drive))
    rolled = v + (drive - a_res * v / speed.clamp(min=1e-12)) * dt
    rolled = torch.where((rolled * v).sum(1, keepdim=True) < 0.0, torch.zeros_like(v), rolled)  # no reversal
    return torch.where(resting, start * dt, rolled)


class FrozenSensor:
    """Open loop: a feedback source whose observation stays at its value when the episode started.

    The simulation (ball, standing robot), its task values and its failure flag run as before; only what
    the policy (or a controller) sees of the sensor is frozen. Evaluating with and without it shows how
    much a policy relies on the feedback (TrueAdapt, Table I, does the same).
    """

    def __init__(self, inner: Feedback):
        self.inner = inner
        self.name, self.num_obs = inner.name, inner.num_obs
        self.value_names, self.ok_value = inner.value_names, inner.ok_value
        self.frozen: Tensor | None = None

    def reset(self, env_ids: Tensor, q: Tensor) -> None:
        """Reset the inner source and freeze the observation of envs `env_ids` at its new value."""
        self.inner.reset(env_ids, q)
        now = self.inner.observe()
        if self.frozen is None:
            self.frozen = now.clone()
        self.frozen[env_ids] = now[env_ids]

    def step(self, q: Tensor, qd: Tensor, active: Tensor | None = None) -> FeedbackStep:
        """Step the inner source; its values and failures pass, the observation stays frozen."""
        out = self.inner.step(q, qd, active)
        return FeedbackStep(obs=self.observe(), values=out.values, failed=out.failed)

    def observe(self) -> Tensor:
        """The frozen observation (N, num_obs) (the inner one before the first reset)."""
        return self.inner.observe() if self.frozen is None else self.frozen

    def close(self) -> None:
        """Close the inner source."""
        self.inner.close()
