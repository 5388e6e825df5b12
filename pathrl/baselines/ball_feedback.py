"""A model-based ball-on-plate controller: a waiter's tray with feedback from the ball (teacher and baseline).

Per env and decision step (batched, float64; every tensor is (N, ...)):

1. **Time law.** The path segment is followed with a minimum-jerk time law to rest at the segment end. Its
   duration T is the smallest that keeps the plan's joint velocity, acceleration and jerk within
   ``limit_margin`` of the limits and the plate's peak acceleration and jerk below ``plate_acc`` (m/s^2) and
   ``plate_jerk`` (m/s^3), never below ``min_duration``. Every step the law is re-planned as a quintic from
   the arc length the env has counted (with the previous plan's path velocity and acceleration) to the end
   at T: the env counts the joint-space length moved, tilting included, so a plan in path arc length alone
   would see the env declare the end reached early and brake hard.
2. **Tray tilt (feed-forward).** At the end of the next step the plate's normal should point along
   ``a_p - g + (7/5) u``: ``a_p`` the plate's planned acceleration (second difference of the planned plate
   centres ``+-smooth_s`` apart), ``u`` the ball's desired acceleration on the plate; the plate turns about
   the ball (``pivot``). With ``u = 0`` the in-plane specific force vanishes and a ball rolling without slip
   stays where it is (5/7 of the in-plane specific force accelerates it,
   :class:`pathrl.sim.feedback.AnalyticBall`).
3. **Ball feedback.** ``u = -kp x_hat - kd v_hat`` (plate frame, clipped to ``max_ball_acc``), from the
   ball position the policy observes (previous and current, 0.1 s apart): ``v_hat`` their difference,
   ``x_hat`` the position extrapolated ``lead_s`` ahead.
4. **Joint target.** One damped least-squares step from the planned configuration (plus last step's
   correction) keeps the pivot where the plan has it and turns the normal to the desired one (the turn
   about the normal is left free; Jacobian by finite differences).
5. **Tracking.** The end-of-step acceleration follows an implicit PD law on the end-of-step state,
   ``a1 = a_d + kq (q_d - q1(a1)) + kv (v_d - v1(a1))`` (natural frequency ``track_omega``, critically
   damped), and is mapped to the env's action: the valid acceleration range then keeps every limit, and
   the env's braking law takes over at the path end, as for a learned policy.

The controller acts through :meth:`~pathrl.envs.tracking.PathTrackingEnv.step` like a policy and reads
only what a learned policy sees of the ball; the path, the time and the robot state are its privileged
inputs. Call it with the env's observations (``rollout`` does); it notices new episodes by their step
counter.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.baselines.tracking import linear_action, tracking_acceleration
from pathrl.baselines.tray_time_law import TimeLawCfg, TimeLawTable, build_time_laws
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.sim.feedback import GRAVITY, ROLL_FACTOR, USABLE_HALF, plate_pose

__all__ = ["TrayController", "TrayControllerCfg", "min_jerk", "plan_durations", "quintic", "quintic_coefficients",
           "tray_normal"]


@dataclass(frozen=True)
class TrayControllerCfg:
    """Gains and limits of :class:`TrayController` (units: s, m, m/s^2, rad)."""

    min_duration: float = 2.0  # s, shortest time law
    plate_acc: float = 3.0  # m/s^2, peak plate acceleration of the plan
    plate_jerk: float = 5.0  # m/s^3, peak plate jerk of the plan
    limit_margin: float = 0.9  # plan within this share of the joint velocity / acceleration / jerk limits
    smooth_s: float = 0.1  # s, half-width of the plate-acceleration difference
    kp: float = 3.0  # 1/s^2, ball position gain
    kd: float = 2.0  # 1/s, ball velocity gain
    lead_s: float = 0.1  # s, ball position extrapolated by this
    max_ball_acc: float = 0.5  # m/s^2, cap on the commanded ball acceleration
    min_horizon: float = 0.3  # s, a re-plan never aims at the end sooner than this
    track_omega: float = 6.0  # rad/s, joint tracking natural frequency
    dls_lambda: float = 1e-2  # damping of the least-squares correction
    position_weight: float = 1.0  # weight of the pivot rows (1/m) against the normal rows
    ik_iters: int = 1  # damped least-squares steps per decision
    pivot: float = 1.0  # the tilt turns the plate about the ball (1) or about the plate centre (0)
    ball_height: float = 0.029  # m, height of the pivot above the plate mid-plane (a mean ball radius)
    fd_step: float = 1e-6  # rad, finite-difference step of the Jacobian
    law_plate_acc: float = 0.0  # m/s^2: > 0 follows the path-dependent time law of tray_time_law (this plate
    #                             acceleration bound, limit_margin) instead of the single minimum-jerk law
    law_smooth_s: float = 0.4  # s, velocity smoothing of that law


def min_jerk(u: Tensor) -> Tensor:
    """Rest-to-rest minimum-jerk law (normalized position) at normalized time u (clamped to [0, 1])."""
    u = u.clamp(0.0, 1.0)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def quintic_coefficients(p0: Tensor, v0: Tensor, a0: Tensor, p1: Tensor, tau: Tensor) -> Tensor:
    """Coefficients (N, 6) of the quintic from (p0, v0, a0) to (p1, 0, 0) in time tau (all (N,))."""
    d = p1 - p0
    return torch.stack([p0, v0, a0 / 2.0,
                        (20 * d - 12 * v0 * tau - 3 * a0 * tau**2) / (2 * tau**3),
                        (-30 * d + 16 * v0 * tau + 3 * a0 * tau**2) / (2 * tau**4),
                        (12 * d - 6 * v0 * tau - a0 * tau**2) / (2 * tau**5)], dim=-1)


def quintic(coef: Tensor, t: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """Position, velocity and acceleration of quintics `coef` (..., 6) at times t (...) after their start."""
    c = coef.unbind(-1)
    p = c[0] + t * (c[1] + t * (c[2] + t * (c[3] + t * (c[4] + t * c[5]))))
    v = c[1] + t * (2 * c[2] + t * (3 * c[3] + t * (4 * c[4] + t * 5 * c[5])))
    a = 2 * c[2] + t * (6 * c[3] + t * (12 * c[4] + t * 20 * c[5]))
    return p, v, a


def plan_durations(env: PathTrackingEnv, env_ids: Tensor, cfg: TrayControllerCfg, fk: ForwardKinematics,
                   samples: int = 60) -> Tensor:
    """Duration T (len(env_ids),) of each env's time law (module docstring, step 1).

    For a law of duration T, velocity scales as 1/T, acceleration as 1/T^2 and jerk as 1/T^3; they are
    evaluated for T = 1 on `samples` instants by finite differences of the path positions.
    """
    n = len(env_ids)
    path, s0, s1 = env.seg_path[env_ids], env.start_s[env_ids], env.end_s[env_ids]
    h = 1.0 / samples
    u = torch.linspace(-2 * h, 1 + 2 * h, samples + 5, dtype=torch.float64, device=s0.device)  # (S,)
    s = s0.unsqueeze(1) + (s1 - s0).unsqueeze(1) * min_jerk(u).unsqueeze(0)  # (n, S)
    q = env.paths.position_at(path.repeat_interleave(len(u)), s.reshape(-1)).reshape(n, len(u), -1)
    vel = (q[:, 2:] - q[:, :-2]) / (2 * h)
    acc = (q[:, 2:] - 2 * q[:, 1:-1] + q[:, :-2]) / h**2
    jerk = (q[:, 4:] - 2 * q[:, 3:-1] + 2 * q[:, 1:-3] - q[:, :-4]) / (2 * h**3)
    lim = env.limits
    idx = env.path_index
    m = cfg.limit_margin
    t_v = (vel.abs() / (m * lim.vel[idx])).amax(dim=(1, 2))
    t_a = (acc.abs() / (m * lim.acc[idx])).amax(dim=(1, 2)).sqrt()
    t_j = (jerk.abs() / (m * lim.jerk[idx])).amax(dim=(1, 2)).pow(1.0 / 3.0)
    full = env.pos[env_ids].unsqueeze(1).expand(n, len(u), -1).clone()
    full[:, :, idx] = q
    o, _ = plate_pose(fk, full)
    t_p = ((o[:, 2:] - 2 * o[:, 1:-1] + o[:, :-2]).norm(dim=2) / h**2 / cfg.plate_acc).amax(dim=1).sqrt()
    plate_jerk = (o[:, 4:] - 2 * o[:, 3:-1] + 2 * o[:, 1:-3] - o[:, :-4]).norm(dim=2) / (2 * h**3)
    t_pj = (plate_jerk / cfg.plate_jerk).amax(dim=1).pow(1.0 / 3.0)
    return torch.stack([t_v, t_a, t_j, t_p, t_pj, torch.full_like(t_v, cfg.min_duration)], dim=1).amax(dim=1)


def tray_normal(a_plate: Tensor, u: Tensor) -> Tensor:
    """Plate normal (N, 3) under which a ball rolling without slip accelerates by `u` (N, 3, world frame, in
    the plate plane; m/s^2) relative to a plate accelerating by `a_plate` (N, 3): along a_plate - g + u / f
    (f = 5/7). With u = 0 the in-plane specific force R^T (g - a_plate) vanishes: a waiter's tray."""
    g = torch.tensor([0.0, 0.0, -GRAVITY], dtype=a_plate.dtype, device=a_plate.device)
    n = a_plate - g + u / ROLL_FACTOR
    return n / n.norm(dim=-1, keepdim=True)


class TrayController:
    """The module docstring's controller for the envs of one :class:`PathTrackingEnv` with a ball feedback."""

    def __init__(self, env: PathTrackingEnv, cfg: TrayControllerCfg | None = None):
        if env.feedback is None or env.feedback.name != "ball_on_plate":
            raise ValueError("TrayController needs a ball-on-plate env (task=ball_on_plate)")
        if len(env.path_index) != env.robot.dof:
            raise ValueError(f"TrayController needs every joint on the path; {env.robot.name} has free joints")
        self.env, self.cfg = env, cfg or TrayControllerCfg()
        self.fk = env.fk  # the env's kinematics (its ball's)
        n, d = env.num_envs, env.robot.dof
        f64 = dict(dtype=torch.float64, device=env.device)
        self.duration = torch.ones(n, **f64)
        self.coef = torch.zeros(n, 6, **f64)  # time law s(t) = sum_k coef_k (t - t_plan)^k
        self.t_plan = torch.zeros(n, **f64)
        self.tau = torch.ones(n, **f64)
        self.correction = torch.zeros(n, d, **f64)  # q_d - q_plan at the last decision's target instant
        self.half = torch.tensor(USABLE_HALF, **f64)
        self.laws: TimeLawTable | None = None
        if self.cfg.law_plate_acc > 0:
            law = TimeLawCfg(plate_acc=self.cfg.law_plate_acc, limit_margin=self.cfg.limit_margin,
                             smooth_s=self.cfg.law_smooth_s)
            self.laws = build_time_laws(env.paths, env.limits.vel[env.path_index], env.limits.acc[env.path_index],
                                        self._plate_numpy, law)
        self.t_law = torch.zeros(n, **f64)  # time on the path's law at the last re-plan (path-dependent law)
        self.s_law = torch.zeros(n, **f64)  # the law's arc length then (= the env's, up to the table's rounding)
        self.s_geo = torch.zeros(n, **f64)  # arc length of the nearest path point to the untilted robot then

    def _arc_on_path(self, q: Tensor, back: float = 0.6, ahead: float = 0.1, samples: int = 71) -> Tensor:
        """Arc length (N,) of the point of each env's path nearest to q (N, D), searched from `back` rad
        behind to `ahead` rad past the env's arc length, then projected onto the table's segment."""
        env = self.env
        grid = torch.linspace(-back, ahead, samples, dtype=torch.float64, device=env.device)
        s = (env.s.unsqueeze(1) + grid).clamp(min=0.0).minimum(env.end_s.unsqueeze(1))
        ref = env.paths.position_at(env.seg_path, s)  # (N, S, D)
        k = (ref - q.unsqueeze(1)).norm(dim=2).argmin(dim=1)
        s0 = s.gather(1, k.unsqueeze(1)).squeeze(1)
        step = env.paths.table_step
        p0 = env.paths.position_at(env.seg_path, s0)
        tangent = (env.paths.position_at(env.seg_path, s0 + step) - p0) / step
        tangent = tangent / tangent.norm(dim=1, keepdim=True).clamp(min=1e-12)
        ds = ((q - p0) * tangent).sum(dim=1).clamp(-step, step)
        return (s0 + ds).clamp(min=0.0).minimum(env.end_s)

    def _plate_numpy(self, q) -> object:
        """Plate centres (G, 3) of joint positions (G, D) (numpy in and out; for toppra)."""
        return plate_pose(self.fk, torch.as_tensor(q, dtype=torch.float64, device=self.env.device))[0].cpu().numpy()

    # ------------------------------------------------------------------ plan
    def _plan(self, t: Tensor) -> Tensor:
        """Reference joint positions (N, ..., D) at times t (N, ...) after the last re-plan."""
        env = self.env
        shape = t.shape
        view = (-1, *([1] * (t.dim() - 1)))
        if self.laws is not None:  # the law's progress from the phase the env's arc length gives, added to
            # where the robot is on the path (the env's arc length also counts the tilt's motion)
            ahead = self.laws.arc_at(env.seg_path, self.t_law.view(view) + t - self.t_plan.view(view))
            s = self.s_geo.view(view) + ahead - self.s_law.view(view)
            q = env.paths.position_at(env.seg_path.view(view).expand(shape).reshape(-1), s.reshape(-1))
            return q.reshape(*shape, -1)
        s = quintic(self.coef.view(*view, 6),
                    (t - self.t_plan.view(view)).clamp(min=0.0).minimum(self.tau.view(view)))[0]
        s = torch.minimum(s, env.end_s.view(view))
        path = env.seg_path.view(view).expand(shape)
        q = env.paths.position_at(path.reshape(-1), s.reshape(-1))
        return q.reshape(*shape, -1)

    def _replan(self) -> None:
        """Re-plan every env's time law from the arc length the env has covered (module docstring, step 1)."""
        env = self.env
        now = env.episode_length_buf.to(torch.float64) * env.cfg.dt
        new = env.episode_length_buf == 0
        if self.laws is not None:
            self.correction[new] = 0.0
            self.t_law = self.laws.time_at(env.seg_path, env.s)
            self.s_law = self.laws.arc_at(env.seg_path, self.t_law)
            self.s_geo = self._arc_on_path(env.pos.to(torch.float64) - self.correction)
            self.t_plan = now
            return
        if bool(new.any()):
            ids = new.nonzero().squeeze(1)
            self.duration[ids] = plan_durations(env, ids, self.cfg, self.fk)
            self.correction[ids] = 0.0
        _, v0, a0 = quintic(self.coef, (now - self.t_plan).clamp(min=0.0).minimum(self.tau))
        v0 = torch.where(new, torch.zeros_like(v0), v0)
        a0 = torch.where(new, torch.zeros_like(a0), a0)
        self.tau = (self.duration - now).clamp(min=self.cfg.min_horizon)
        self.t_plan = now
        self.coef = quintic_coefficients(env.s, v0, a0, env.end_s, self.tau)

    # ------------------------------------------------------------------ control
    def ball_acceleration(self, ball_obs: Tensor) -> Tensor:
        """Desired ball acceleration on the plate (N, 2), plate frame (m/s^2), from the ball state (N, 4):
        previous and current position relative to the usable half-size."""
        c = self.cfg
        prev, cur = ball_obs[:, :2] * self.half, ball_obs[:, 2:4] * self.half
        vel = (cur - prev) / self.env.cfg.dt
        u = -c.kp * (cur + c.lead_s * vel) - c.kd * vel
        norm = u.norm(dim=1, keepdim=True)
        return u * (c.max_ball_acc / norm.clamp(min=c.max_ball_acc))

    def target(self, ball_obs: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Desired position, velocity and acceleration (N, D) at the end of the next decision step."""
        env, c = self.env, self.cfg
        dt = env.cfg.dt
        t1 = (env.episode_length_buf.to(torch.float64) + 1.0) * dt
        h = c.smooth_s
        offsets = torch.tensor([-h, 0.0, h], dtype=torch.float64, device=env.device)
        q3 = self._plan(t1.unsqueeze(1) + offsets)  # (N, 3, D)
        o3, r3 = plate_pose(self.fk, q3)
        a_plate = (o3[:, 2] - 2 * o3[:, 1] + o3[:, 0]) / h**2
        _, rot_now = plate_pose(self.fk, env.pos)
        u = self.ball_acceleration(ball_obs)
        u_world = rot_now[:, :, 0] * u[:, :1] + rot_now[:, :, 1] * u[:, 1:]
        normal = tray_normal(a_plate, u_world)
        q_plan = q3[:, 1]
        # pivot: the ball's centre as a point of the plate; the tilt turns the plate about it
        pivot = torch.cat([ball_obs[:, 2:4] * self.half * c.pivot,
                           torch.full_like(ball_obs[:, :1], c.ball_height)], dim=1)
        goal = o3[:, 1] + (r3[:, 1] @ pivot.unsqueeze(2)).squeeze(2)
        q_d = q_plan + self.correction
        for _ in range(int(c.ik_iters)):
            q_d = self._tilt(q_d, goal, normal, pivot)
        corr = q_d - q_plan
        v_plan = (q3[:, 2] - q3[:, 0]) / (2 * h)
        a_plan = (q3[:, 2] - 2 * q3[:, 1] + q3[:, 0]) / h**2
        v_d = v_plan + (corr - self.correction) / dt
        self.correction = corr
        return q_d, v_d, a_plan

    def _tilt(self, q: Tensor, o_target: Tensor, normal: Tensor, pivot: Tensor) -> Tensor:
        """One damped least-squares step from q (N, D): the plate point `pivot` (N, 3, plate frame) to
        o_target, the normal to `normal` (N, 3)."""
        c = self.cfg
        n, d = q.shape
        eye = torch.eye(d, dtype=q.dtype, device=q.device)
        qs = torch.cat([q.unsqueeze(1), q.unsqueeze(1) + c.fd_step * eye], dim=1)  # (N, 1 + D, D)
        o, r = plate_pose(self.fk, qs)
        o = o + (r @ pivot.unsqueeze(1).unsqueeze(3)).squeeze(3)
        nz = r[..., :, 2]
        jac = torch.cat([o[:, 1:] - o[:, :1], nz[:, 1:] - nz[:, :1]], dim=2).transpose(1, 2) / c.fd_step  # (N, 6, D)
        e = torch.stack([r[:, 0, :, 0], r[:, 0, :, 1]], dim=1)  # plate x, y axes (N, 2, 3)
        w = c.position_weight
        a = torch.cat([w * jac[:, :3], e @ jac[:, 3:]], dim=1)  # (N, 5, D)
        b = torch.cat([w * (o_target - o[:, 0]), (e @ (normal - nz[:, 0]).unsqueeze(2)).squeeze(2)], dim=1)
        hess = a.transpose(1, 2) @ a + c.dls_lambda * eye
        return q + torch.linalg.solve(hess, (a.transpose(1, 2) @ b.unsqueeze(2))).squeeze(2)

    def accelerations(self, ball_obs: Tensor) -> Tensor:
        """End-of-step accelerations (N, D) of the tracking law (module docstring, step 5)."""
        env = self.env
        q_d, v_d, a_d = self.target(ball_obs)
        return tracking_acceleration(env.pos, env.vel, env.acc, q_d, v_d, a_d, env.cfg.dt, self.cfg.track_omega)

    def __call__(self, obs: TensorDict) -> Tensor:
        """Actions (N, D) in [-1, 1] for the env's current state; `obs` is the env's observation."""
        env = self.env
        self._replan()
        ball = env.feedback.observe()[:, :4].to(torch.float64)
        a1 = self.accelerations(ball)
        return linear_action(a1, env.a_min, env.a_max).to(torch.float32)
