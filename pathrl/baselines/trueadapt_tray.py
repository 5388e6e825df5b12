"""A model-based controller for TrueAdapt (:class:`~pathrl.envs.trueadapt.TrueAdaptEnv`): follow the reference
trajectory and tilt the plate like a waiter's tray, with feedback from the measured ball position.

Per decision step (batched over envs, float64; every tensor is (N, ...)), for the end of the next step t1:

1. **Reference.** ``q_ref, v_ref, a_ref`` at sample i + 1 of each env's reference (the bank's samples and replay
   accelerations; the velocities are their trapezoidal integral from rest, exactly what the env's linear
   acceleration interpolation produces). The plate's reference acceleration ``a_p`` at t1 is the central second
   difference of the plate centres at samples i, i + 1, i + 2 (forward kinematics).
2. **Ball feedback** (plate frame, m and m/s^2). The ball's wanted acceleration relative to the plate is
   ``u = -kp (e + lead_s v) - kd v`` with ``e`` the measured position minus the target (on plate: the plate
   centre; in place: the first measurement of the episode) and ``v`` the difference of the current and the
   previous measurement over dt; ``|u|`` is capped at ``max_ball_acc`` and low-passed (time constant
   ``filter_s``; the 2 mm sensor noise makes the difference velocity noisy). The design is a PD on the
   analytic model ``x'' = u`` (see :func:`pd_gains`).
3. **Tray tilt.** The plate's normal at t1 should point along ``ff * a_p - g + u / f`` (f = 5/7, the
   acceleration of a solid ball rolling without slip per unit in-plane specific force;
   :func:`pathrl.baselines.ball_feedback.tray_normal`): with u = 0 the ball feels no in-plane force, with u it
   accelerates by u. The normal's angle from the vertical is capped at ``max_tilt``.
4. **Joint target.** A Gauss-Newton step (``ik_iters``) from ``q_ref`` finds the configuration ``q_d`` whose
   plate normal is the wanted one while the plate point under the ball stays where the reference has it,
   penalising the deviation from the reference (``dls_lambda |q_d - q_ref|^2``; the turn about the normal is
   free). The deviation ``q_d - q_ref`` is capped per joint at ``max_correction`` (well below the env's
   10 deg termination).
5. **Tracking.** The end-of-step acceleration follows the implicit critically damped PD law
   (:func:`pathrl.baselines.tracking.tracking_acceleration`, ``track_omega``) towards ``q_d``, ``v_ref`` plus
   ``rate_feedforward`` times the correction's rate of change, and ``a_ref``; the action is that
   acceleration / a_max, so the env's valid range (eq. 8) clips it like a policy's and every limit holds.

The controller reads the env's state and reference (privileged) and only the measured ball positions a policy
observes. It keeps its last correction and its filtered command (tensors, which
:class:`pathrl.policy.residual.ControllerObs` snapshots for a resume) and notices new episodes by their step counter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor

from pathrl.baselines.ball_feedback import tray_normal
from pathrl.baselines.tracking import tracking_acceleration
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.sim.feedback import plate_pose

__all__ = ["AdaptTrayCfg", "AdaptTrayController", "ball_command", "cap_tilt", "pd_gains", "reference_velocities",
           "tilt_ik"]


@dataclass(frozen=True)
class AdaptTrayCfg:
    """Gains and caps of :class:`AdaptTrayController` (units: s, m, m/s^2, rad)."""

    kp: float = 0.49  # 1/s^2, ball position gain (pd_gains(0.7, 0.5))
    kd: float = 0.7  # 1/s, ball velocity gain
    lead_s: float = 0.0  # s, ball position extrapolated by this before the position gain
    max_ball_acc: float = 0.6  # m/s^2, cap on the wanted ball acceleration |u|
    filter_s: float = 0.1  # s, time constant of the first-order low-pass on u (0: none)
    rate_feedforward: float = 1.0  # share of the correction's rate of change fed forward as velocity
    feedforward: float = 1.0  # scale of the reference's plate acceleration in the tilt (0: feedback only)
    max_tilt: float = 0.15  # rad, cap on the plate normal's angle from the vertical
    track_omega: float = 4.0  # rad/s, joint tracking natural frequency (critically damped)
    dls_lambda: float = 1e-3  # weight of |q_d - q_ref|^2 in the Gauss-Newton step
    ik_iters: int = 2  # Gauss-Newton steps per decision
    max_correction: float = 0.14  # rad, cap on |q_d - q_ref| per joint (the env terminates beyond 0.1745)
    ball_height: float = 0.028  # m, the pivot (ball centre) above the plate mid-plane
    fd_step: float = 1e-6  # rad, finite-difference step of the Jacobian

    def __post_init__(self) -> None:
        """One-line ValueError for a value that would run but give a wrong result."""
        for key in ("kp", "kd", "lead_s", "max_ball_acc", "feedforward", "dls_lambda", "ball_height", "filter_s",
                    "rate_feedforward"):
            if not float(getattr(self, key)) >= 0.0:
                raise ValueError(f"controller trueadapt_tray: {key} must be >= 0, got {getattr(self, key)}")
        for key in ("max_tilt", "track_omega", "max_correction", "fd_step"):
            if not float(getattr(self, key)) > 0.0:
                raise ValueError(f"controller trueadapt_tray: {key} must be > 0, got {getattr(self, key)}")
        if not float(self.max_tilt) < math.pi / 2 or int(self.ik_iters) < 1:
            raise ValueError(f"controller trueadapt_tray: max_tilt must be < pi/2 and ik_iters >= 1; got "
                             f"{self.max_tilt}, {self.ik_iters}")


def pd_gains(omega: float, zeta: float) -> tuple[float, float]:
    """(kp, kd) placing the poles of the ball model ``x'' = u``, ``u = -kp x - kd x'`` at natural frequency omega
    (rad/s) and damping ratio zeta: ``s^2 + kd s + kp = s^2 + 2 zeta omega s + omega^2``."""
    return omega * omega, 2.0 * zeta * omega


def reference_velocities(acc: Tensor, dt: float) -> Tensor:
    """Velocities (P, T, D) at the samples of trajectories replayed from rest with accelerations `acc` (P, T, D)
    interpolated linearly over steps of dt: the trapezoidal integral ``v_k = sum_{j<k} dt (a_j + a_{j+1}) / 2``."""
    inc = 0.5 * dt * (acc[:, 1:] + acc[:, :-1])
    return torch.cat([torch.zeros_like(acc[:, :1]), inc.cumsum(dim=1)], dim=1)


def ball_command(meas: Tensor, prev: Tensor, target: Tensor, dt: float, cfg: AdaptTrayCfg) -> Tensor:
    """Wanted ball acceleration (N, 2) relative to the plate (plate frame, m/s^2) from the current and previous
    measured ball positions and the target position (all (N, 2), m), measurements dt apart (step 2)."""
    vel = (meas - prev) / dt
    u = -cfg.kp * (meas - target + cfg.lead_s * vel) - cfg.kd * vel
    norm = u.norm(dim=1, keepdim=True)
    return u * (cfg.max_ball_acc / norm.clamp(min=max(cfg.max_ball_acc, 1e-12)))


def cap_tilt(normal: Tensor, max_tilt: float) -> Tensor:
    """Unit normals (N, 3) whose angle from the vertical exceeds max_tilt (rad) turned, in their vertical plane, to
    exactly max_tilt; the others unchanged."""
    horiz = normal[:, :2]
    h = horiz.norm(dim=1, keepdim=True)
    steep = torch.atan2(h, normal[:, 2:]) > max_tilt
    capped = torch.cat([horiz / h.clamp(min=1e-12) * math.sin(max_tilt),
                        torch.full_like(h, math.cos(max_tilt))], dim=1)
    return torch.where(steep, capped, normal)


def tilt_ik(fk: ForwardKinematics, q_ref: Tensor, goal: Tensor, normal: Tensor, pivot: Tensor,
            cfg: AdaptTrayCfg) -> Tensor:
    """Configuration (N, D) near q_ref (N, D) whose plate point `pivot` (N, 3, plate frame) is at `goal` (N, 3,
    world) and whose plate normal is `normal` (N, 3); Gauss-Newton steps of
    ``min |o(q) - goal|^2 + |E (n(q) - normal)|^2 + lam |q - q_ref|^2`` (E: the plate's x and y axes)."""
    n, d = q_ref.shape
    eye = torch.eye(d, dtype=q_ref.dtype, device=q_ref.device)
    q = q_ref.clone()
    for _ in range(int(cfg.ik_iters)):
        qs = torch.cat([q.unsqueeze(1), q.unsqueeze(1) + cfg.fd_step * eye], dim=1)  # (N, 1 + D, D)
        o, r = plate_pose(fk, qs)
        o = o + (r @ pivot.unsqueeze(1).unsqueeze(3)).squeeze(3)
        nz = r[..., :, 2]
        jac = torch.cat([o[:, 1:] - o[:, :1], nz[:, 1:] - nz[:, :1]], dim=2).transpose(1, 2) / cfg.fd_step
        e = torch.stack([r[:, 0, :, 0], r[:, 0, :, 1]], dim=1)  # (N, 2, 3)
        a = torch.cat([jac[:, :3], e @ jac[:, 3:]], dim=1)  # (N, 5, D)
        b = torch.cat([goal - o[:, 0], (e @ (normal - nz[:, 0]).unsqueeze(2)).squeeze(2)], dim=1)
        lhs = a.transpose(1, 2) @ a + cfg.dls_lambda * eye
        rhs = (a.transpose(1, 2) @ b.unsqueeze(2)).squeeze(2) - cfg.dls_lambda * (q - q_ref)
        q = q + torch.linalg.solve(lhs, rhs.unsqueeze(2)).squeeze(2)
    return q


class AdaptTrayController:
    """The module docstring's controller for the envs of one TrueAdapt env; ``controller(obs)`` -> actions (N, D)."""

    def __init__(self, env: Any, cfg: AdaptTrayCfg | None = None):
        if not hasattr(env, "reference_actions") or not hasattr(env, "bank"):
            raise ValueError("controller trueadapt_tray: needs a trajectory-adaptation env (task=trueadapt_*)")
        self.env, self.cfg = env, cfg or AdaptTrayCfg()
        self.fk = env.fk  # the env's kinematics (its ball's)
        # constant tables live in a dict: ControllerObs snapshots only the controller's tensor attributes
        self.tables = {"vel": reference_velocities(env.bank.acc, env.cfg.dt)}
        self.correction = torch.zeros(env.num_envs, env.robot.dof, dtype=torch.float64, device=env.device)
        self.u = torch.zeros(env.num_envs, 2, dtype=torch.float64, device=env.device)  # low-passed ball command

    def reference(self, offset: int) -> tuple[Tensor, Tensor, Tensor]:
        """Reference position, velocity and acceleration (N, D) `offset` samples after the current one."""
        env = self.env
        i = (env.episode_length_buf + offset).clamp(max=env.bank.steps[env.traj])
        return env.bank.pos[env.traj, i], self.tables["vel"][env.traj, i], env.bank.acc[env.traj, i]

    def plate_acceleration(self) -> tuple[Tensor, Tensor, Tensor]:
        """The reference's plate acceleration (N, 3) at the next sample, and the plate centre (N, 3) and rotation
        (N, 3, 3) there."""
        env = self.env
        q = torch.stack([self.reference(k)[0] for k in (0, 1, 2)], dim=1)
        o, r = plate_pose(self.fk, q)
        return (o[:, 2] - 2.0 * o[:, 1] + o[:, 0]) / env.cfg.dt**2, o[:, 1], r[:, 1]

    def ball_target(self) -> Tensor:
        """Where the ball should be (N, 2), plate frame: the centre on plate, the start in place."""
        env = self.env
        return env.start_meas if env.cfg.mode == "in_place" else torch.zeros_like(env.meas)

    def target(self) -> tuple[Tensor, Tensor, Tensor]:
        """Desired position, velocity and acceleration (N, D) at the end of the next step (steps 1-4)."""
        env, c = self.env, self.cfg
        dt = env.cfg.dt
        new = env.episode_length_buf == 0
        self.correction[new] = 0.0
        q_ref, v_ref, a_ref = self.reference(1)
        a_p, o_ref, r_ref = self.plate_acceleration()
        raw = ball_command(env.meas, env.prev_meas, self.ball_target(), dt, c)
        alpha = dt / (c.filter_s + dt)
        self.u = torch.where(new.unsqueeze(1), raw, self.u + alpha * (raw - self.u))
        u = self.u
        _, r_now = plate_pose(self.fk, env.pos)
        u_world = r_now[:, :, 0] * u[:, :1] + r_now[:, :, 1] * u[:, 1:]
        normal = cap_tilt(tray_normal(c.feedforward * a_p, u_world), c.max_tilt)
        xy = torch.maximum(torch.minimum(env.meas, env.half), -env.half)
        pivot = torch.cat([xy, torch.full_like(xy[:, :1], c.ball_height)], dim=1)
        goal = o_ref + (r_ref @ pivot.unsqueeze(2)).squeeze(2)
        q_d = tilt_ik(self.fk, q_ref, goal, normal, pivot, c)
        corr = (q_d - q_ref).clamp(-c.max_correction, c.max_correction)
        v_d = v_ref + c.rate_feedforward * (corr - self.correction) / dt
        self.correction = corr
        return q_ref + corr, v_d, a_ref

    def __call__(self, obs: Any = None) -> Tensor:
        """Actions (N, D) in [-1, 1] (acceleration / a_max; the env clips them into its valid range)."""
        env = self.env
        q_d, v_d, a_d = self.target()
        a1 = tracking_acceleration(env.pos, env.vel, env.acc, q_d, v_d, a_d, env.cfg.dt, self.cfg.track_omega)
        return (a1 / env.limits.acc).clamp(-1.0, 1.0).to(torch.float32)

