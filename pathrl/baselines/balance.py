"""Leg balance for the free-standing ARMAR-4, composed with a policy that moves the upper body.

The upper body (the path joints) follows a shipped policy network; the leg joints (the free joints) follow a
corrected standing posture q* (docs/lab/armar4_balance.md):

    COM       static centre of mass of the commanded posture (ankles at 0) relative to the ankles (x forward,
              z up; :class:`pathrl.baselines.com.StaticCom`): the ankles lean the body forward by
              k_com (com_forward - x) / z (rad, small angles), keeping the COM off the heels
    tilt      foot tilt t = measured pelvis lean (forward, left; rad) minus the lean the commanded leg joints give
              the pelvis with flat feet; rate t' over the decision step
    ankles    through pinv(ankle axes) per leg, the feet turn the body by kp_ankle t + kd_ankle t' back against
              the tilt, plus the COM lean and lean_bias (ankle strategy)
    hips      kp_hip, kd_hip through pinv(hip axes): the trunk turns back on the legs (hip strategy)
    joints    each leg joint accelerates to q* (clipped to +-max_correction) as a critically damped second-order
              system: a = omega^2 (q* - q) - 2 omega v
    dynamic   (off by default) from the upper body's accelerations of the next step (the network's actions):
              ``preview`` takes the static COM of the path joints' posture q + v preview; ``k_zmp`` adds that share
              of the zero-moment point's dynamic shift to the COM error; the ZMP guard (``zmp_min``, ``zmp_max``)
              changes the ankles' lean acceleration so that the ZMP of the whole commanded motion at the end of the
              next step stays in a band over the feet (:meth:`pathrl.baselines.com.StaticCom.zmp`)

The accelerations are returned as actions of the env's free-joint mapping (``posture``: minus the env's own pull
to the start posture, so that the env applies ``a``; ``centred``: directly). Joint axes come from the robot's URDF
at the zero posture (PyBullet, DIRECT mode); the legs stay close to it while standing. The measured defaults use
the COM feedforward only: feedback on the tilt oscillated in PyBullet (the docs have the numbers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import Tensor

from pathrl.baselines.com import StaticCom
from pathrl.limits.feasible import acceleration_to_action, action_to_acceleration
from pathrl.limits.integrate import end_of_step

__all__ = ["BalanceCfg", "BalanceController", "BalanceLaw", "chain_matrix", "correction_matrix", "lean_rotation",
           "lean_vector", "leg_groups", "urdf_joint_axes"]


@dataclass(frozen=True)
class BalanceCfg:
    """Gains of the leg balance law; ``policy``: model directory whose network moves the upper body."""

    policy: str = "models/tracking/armar4_legs_target_point_balancing"
    kp_ankle: float = 0.0  # ankle correction per rad of foot tilt (rad/rad); > 0 oscillated in PyBullet (docs)
    kd_ankle: float = 0.0  # ankle correction per rad/s of foot tilt rate (rad s/rad)
    kp_hip: float = 0.0  # hip correction per rad of foot tilt
    kd_hip: float = 0.0  # hip correction per rad/s of foot tilt rate
    lean_bias: float = 0.0  # constant forward lean (rad) the ankles give the body
    k_com: float = 1.0  # share of the static COM error (commanded posture) the ankles lean away (0: off, 1: all)
    com_forward: float = 0.02  # where the static COM should be: this far (m) ahead of the ankles
    omega: float = 3.0  # natural frequency of the legs following their corrected posture (rad/s)
    max_correction: float = 0.3  # |corrected posture| of a leg joint (rad)
    policy_legs: float = 0.0  # weight of the policy's own leg actions added to the balance law's (0: replaced)
    # dynamic terms (docs/lab/armar4_balance.md, section 5); all off by default, which is the static law above
    k_zmp: float = 0.0  # share of the upper body's dynamic ZMP shift (next step) added to the static COM error
    preview: float = 0.0  # s: the static COM of the upper body's posture this far ahead (q + v preview)
    zmp_min: float = -math.inf  # m: lowest ZMP (relative to the ankles) the legs let the next step command
    zmp_max: float = math.inf  # m: highest ZMP the legs let the next step command
    ankle_height: float = 0.086  # m, ankle joints above the floor (StandingScene; the ZMP lies on the floor)

    @property
    def dynamic(self) -> bool:
        """Whether any dynamic term is on (it needs the upper body's accelerations of the next step)."""
        return bool(self.k_zmp or self.preview or math.isfinite(self.zmp_min) or math.isfinite(self.zmp_max))

    def __post_init__(self) -> None:
        for key in ("omega", "max_correction"):
            if not float(getattr(self, key)) > 0.0:
                raise ValueError(f"controller balance: {key} must be > 0, got {getattr(self, key)}")
        if not float(self.preview) >= 0.0 or not float(self.zmp_min) < float(self.zmp_max):
            raise ValueError(f"controller balance: needs preview >= 0 and zmp_min < zmp_max, got {self.preview}, "
                             f"{self.zmp_min}, {self.zmp_max}")


def lean_vector(quat_xyzw: Tensor) -> Tensor:
    """(forward, left) lean (N, 2) in rad of a body whose world orientation is `quat_xyzw` (N, 4): the angles of
    its z axis towards world +x and +y (atan2 of the z axis' x, y components over its z component)."""
    x, y, z, w = quat_xyzw.unbind(-1)
    zx = 2.0 * (x * z + w * y)
    zy = 2.0 * (y * z - w * x)
    zz = 1.0 - 2.0 * (x * x + y * y)
    return torch.stack([torch.atan2(zx, zz), torch.atan2(zy, zz)], dim=-1)


def lean_rotation(lean: Tensor) -> Tensor:
    """The rotation vector (N, 3) (world frame, rad) that leans an upright body by `lean` (N, 2) (forward, left)."""
    return torch.stack([-lean[:, 1], lean[:, 0], torch.zeros_like(lean[:, 0])], dim=1)


def correction_matrix(axes: np.ndarray, groups: list[list[int]]) -> np.ndarray:
    """Joint angle per unit of body rotation, (J, 3): for each group of joints (one leg's ankles or hips, with
    world `axes` (J, 3) of a child turning about them relative to its parent) the least-squares joint angles that
    turn the child by -w relative to the parent for a parent rotation w, i.e. rows -pinv(A_group)."""
    m = np.zeros((len(axes), 3))
    for g in groups:
        m[g] = -np.linalg.pinv(axes[g].T)
    return m


def urdf_joint_axes(robot: Any, joints: list[str]) -> tuple[np.ndarray, list[str]]:
    """World-frame axes (J, 3) of `joints` of `robot`'s URDF with every joint at 0 (PyBullet, DIRECT), and the
    names of their child links."""
    import pybullet as p

    from pathrl.sim.scene import load_urdf

    cid = p.connect(p.DIRECT)
    try:
        body = load_urdf(cid, robot.urdf, fixed_base=True)
        names = {p.getJointInfo(body, j, physicsClientId=cid)[1].decode(): j
                 for j in range(p.getNumJoints(body, physicsClientId=cid))}
        out, links = np.zeros((len(joints), 3)), []
        for k, name in enumerate(joints):
            info = p.getJointInfo(body, names[name], physicsClientId=cid)
            rot = p.getLinkState(body, names[name], computeForwardKinematics=True, physicsClientId=cid)[5]
            out[k] = np.asarray(p.getMatrixFromQuaternion(rot)).reshape(3, 3) @ np.asarray(info[13])
            links.append(info[12].decode())
        return out, links
    finally:
        p.disconnect(physicsClientId=cid)


def chain_matrix(axes: np.ndarray, legs: list[list[int]]) -> np.ndarray:
    """Pelvis rotation (world frame, rad) per joint angle of the legs, (3, J), small angles: with the feet flat
    on the floor, leg joint j turns the pelvis by -axis_j q_j; averaged over the legs."""
    m = np.zeros((3, len(axes)))
    for g in legs:
        m[:, g] = -axes[g].T / len(legs)
    return m


def leg_groups(names: list[str], key: str) -> list[list[int]]:
    """Indices into `names` of the joints containing `key` (``ank``, ``hip``), one list per leg suffix."""
    legs: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        if key in n:
            legs.setdefault(n.rsplit("_", 1)[-1], []).append(i)
    return list(legs.values())


class BalanceLaw:
    """The leg part, pure and batched: the foot tilt and the corrected leg posture (N, J)."""

    def __init__(self, cfg: BalanceCfg, ankle: np.ndarray, hip: np.ndarray, chain: np.ndarray):
        self.cfg = cfg
        self.ankle = torch.as_tensor(ankle, dtype=torch.float64)  # (J, 3) joint angle per unit body rotation
        self.hip = torch.as_tensor(hip, dtype=torch.float64)
        self.chain = torch.as_tensor(chain, dtype=torch.float64)  # (3, J) pelvis rotation per joint angle

    def tilt(self, lean: Tensor, q: Tensor) -> Tensor:
        """Foot tilt (N, 2) rad: the measured lean (N, 2) minus the lean the leg posture q (N, J) gives the pelvis
        with both feet flat. The legs lean the body on purpose; only the rest is the robot tipping (and its
        compliance), and only the rest is fed back (feeding back the whole lean closes a loop through the legs'
        own lagging motion, which oscillates)."""
        w = q @ self.chain.T  # (N, 3)
        return lean - torch.stack([w[:, 1], -w[:, 0]], dim=1)

    def com_lean(self, offset: Tensor) -> Tensor:
        """Body lean (N, 2) (forward, left; rad) that puts the static COM, at `offset` (N, 3) m from the ankles with
        the ankles at 0, at ``com_forward`` ahead of them, scaled by ``k_com`` (small angles: lean = shift / height).
        Forward only: with both feet on the floor the ankle roll joints cannot lean the body sideways."""
        c = self.cfg
        shift = torch.stack([c.com_forward - offset[:, 0], torch.zeros_like(offset[:, 1])], dim=1)
        return c.k_com * shift / offset[:, 2:3].clamp(min=0.1)

    def posture(self, tilt: Tensor, tilt_rate: Tensor, lean_ff: Tensor | None = None) -> Tensor:
        """Corrected leg posture (N, J) in rad for the foot tilt and its rate (N, 2) (rad, rad/s), plus a wanted
        body lean `lean_ff` (N, 2) (rad; the static COM feedforward) that the ankles give."""
        c = self.cfg
        bias = torch.zeros_like(tilt)
        bias[:, 0] = c.lean_bias
        if lean_ff is not None:
            bias = bias + lean_ff
        w_ank = lean_rotation(c.kp_ankle * tilt + c.kd_ankle * tilt_rate - bias)
        w_hip = lean_rotation(c.kp_hip * tilt + c.kd_hip * tilt_rate)
        q = w_ank @ (-self.ankle).T + w_hip @ (-self.hip).T  # the body turns by -w: against its lean
        return q.clamp(-c.max_correction, c.max_correction)

    def acceleration(self, q_star: Tensor, q: Tensor, v: Tensor) -> Tensor:
        """Leg accelerations (N, J) towards `q_star` (critically damped, natural frequency omega)."""
        w = self.cfg.omega
        return (w * w) * (q_star - q) - (2.0 * w) * v


class BalanceController:
    """Upper body from a policy network, legs from :class:`BalanceLaw`; ``__call__(obs) -> (N, num_actions)``."""

    def __init__(self, env: Any, cfg: BalanceCfg | None = None, upper: Any = None):
        self.env, self.cfg = env, cfg or BalanceCfg()
        if env.feedback is None or env.feedback.name != "standing":
            raise ValueError("controller balance: needs a free-standing env (task=standing)")
        robot = env.robot
        self.free = torch.nonzero(env.hold).squeeze(1) if env.cfg.free_joint_actions != "linear" else None
        if self.free is None or len(self.free) == 0:
            raise ValueError("controller balance: needs free leg joints (env.free_joint_actions centred | posture)")
        names = [robot.joints[i] for i in self.free.tolist()]
        axes, links = urdf_joint_axes(robot, names)
        ankles = leg_groups(names, "ank")
        self.ankles = self.free[[i for g in ankles for i in g]]
        use_com = self.cfg.k_com or self.cfg.dynamic
        self.com = StaticCom(robot, [links[g[-1]] for g in ankles]) if use_com else None  # feet: last ankles
        self.law = BalanceLaw(self.cfg, correction_matrix(axes, ankles),
                              correction_matrix(axes, leg_groups(names, "hip")),
                              chain_matrix(axes, leg_groups(names, "_")))
        unit = torch.tensor([[1.0, 0.0]], dtype=torch.float64)
        self.lean_dir = (lean_rotation(unit) @ self.law.ankle.T)[0]  # (J,) ankle angles per rad forward lean
        self.upper = upper  # the upper body's network (None: at rest); pathrl.runs.make_controller loads cfg.policy
        self.prev_tilt = torch.zeros(env.num_envs, 2, dtype=torch.float64)

    def tilt(self) -> tuple[Tensor, Tensor]:
        """Foot tilt (N, 2) rad and its rate (N, 2) rad/s over the last step; the rate is 0 on an episode's first
        step."""
        lean = lean_vector(self.env.feedback.reading[:, 3:7].to(torch.float64))
        tilt = self.law.tilt(lean, self.env.pos[:, self.free])
        fresh = (self.env.episode_length_buf == 0).unsqueeze(1)
        rate = torch.where(fresh, torch.zeros_like(tilt), (tilt - self.prev_tilt) / self.env.cfg.dt)
        self.prev_tilt = tilt
        return tilt, rate

    def next_state(self, acc: Tensor) -> tuple[Tensor, Tensor]:
        """Commanded positions and velocities (N, D) at the end of the next step for the accelerations `acc`
        (N, D) at its end (the env's integration)."""
        return end_of_step(self.env.pos, self.env.vel, self.env.acc, acc, self.env.cfg.dt)

    def com_offset(self, upper_acc: Tensor | None = None) -> Tensor:
        """Static COM (N, 3) m of the commanded posture with the ankles at 0, relative to the ankles; with
        ``preview`` that of the path joints' posture ``preview`` s ahead (q + v preview, inside the position
        limits), and with ``k_zmp`` the x part moved by that share of the dynamic ZMP shift (ZMP minus static COM)
        that the upper body's accelerations `upper_acc` (N, D) give at the end of the next step, legs still."""
        env, c = self.env, self.cfg
        q0 = env.pos.clone()
        q0[:, self.ankles] = 0.0
        if c.preview > 0.0:
            p = env.path_index
            lim = env.limits.pos[p].to(q0)
            q0[:, p] = torch.minimum(torch.maximum(q0[:, p] + c.preview * env.vel[:, p], lim[:, 0]), lim[:, 1])
        off = self.com.offset(q0)
        if c.k_zmp and upper_acc is not None:
            f = self.free
            q1, v1 = self.next_state(upper_acc)
            q1[:, f], v1[:, f] = env.pos[:, f], 0.0
            q1[:, self.ankles] = 0.0
            a1 = upper_acc.clone()
            a1[:, f] = 0.0
            zmp, _ = self.com.zmp(q1, v1, a1, c.ankle_height)
            off = off.clone()
            off[:, 0] += c.k_zmp * (zmp[:, 0] - self.com.offset(q1)[:, 0])
        return off

    def zmp_guard(self, a_legs: Tensor, upper_acc: Tensor) -> Tensor:
        """Leg accelerations (N, J) whose forward-lean part is changed so that the ZMP of the whole commanded motion
        at the end of the next step stays in [zmp_min, zmp_max] (m, relative to the ankles): the ZMP is affine in
        the ankles' lean acceleration to first order, its slope is measured with +1 rad/s^2 of forward lean."""
        c, f = self.cfg, self.free
        acc = upper_acc.clone()
        acc[:, f] = a_legs
        step = acc.clone()
        step[:, f] += self.lean_dir
        x0 = self.com.zmp(*self.next_state(acc), acc, c.ankle_height)[0][:, 0]
        x1 = self.com.zmp(*self.next_state(step), step, c.ankle_height)[0][:, 0]
        slope = x1 - x0  # m per rad/s^2, about -0.1: leaning forward faster pushes the ZMP back
        shift = torch.where(slope < -0.01, (x0.clamp(c.zmp_min, c.zmp_max) - x0) / slope.clamp(max=-0.01), 0.0)
        return a_legs + shift[:, None] * self.lean_dir

    def leg_actions(self, upper_acc: Tensor | None = None) -> Tensor:
        """Actions (N, J) of the free joints that make the env apply the balance law's accelerations; the dynamic
        terms need the upper body's accelerations `upper_acc` (N, D) at the end of the next step."""
        env, f, c = self.env, self.free, self.cfg
        tilt, rate = self.tilt()
        q, v = env.pos[:, f], env.vel[:, f]
        ff = self.law.com_lean(self.com_offset(upper_acc)) if self.com is not None else None
        a = self.law.acceleration(self.law.posture(tilt, rate, ff), q, v)
        if upper_acc is not None and (math.isfinite(c.zmp_min) or math.isfinite(c.zmp_max)):
            a = self.zmp_guard(a, upper_acc)
        lo, hi = env.a_min[:, f], env.a_max[:, f]
        act = acceleration_to_action(a, lo, hi)
        if env.cfg.free_joint_actions == "posture":  # the env adds its pull to the start posture: take it off
            w = env.cfg.posture_omega
            act = act - acceleration_to_action(-(w * w) * q - (2.0 * w) * v, lo, hi)
        return act.clamp(-1.0, 1.0)

    def __call__(self, obs: Any) -> Tensor:
        with torch.no_grad():
            out = self.upper(obs).to(torch.float64).clone() if self.upper is not None else \
                torch.zeros(self.env.num_envs, self.env.num_actions, dtype=torch.float64)
        upper_acc = None
        if self.cfg.dynamic:  # the path joints' accelerations at the end of the next step (the env's mapping)
            upper_acc = action_to_acceleration(out.to(self.env.a_min), self.env.a_min, self.env.a_max, self.env.hold)
        legs = self.leg_actions(upper_acc) + self.cfg.policy_legs * out[:, self.free]
        out[:, self.free] = legs.clamp(-1.0, 1.0)
        return out.to(torch.float32)
