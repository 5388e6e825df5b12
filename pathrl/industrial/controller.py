"""The simulated industrial controller, the "black box" that executes a motion program.

``execute(program, v)`` -> :class:`Execution` (TCP positions, tool rotations and joints at ``rate`` Hz):

1. **Path.** The blended geometric path of the program (:func:`pathrl.industrial.program.sample_path`: MoveL
   lines / MoveJ joint lines with parabolic corner blends inside the zone), as joint configurations q(s)
   every ~0.5 mm of TCP arc length s (closed-form IK, one arm configuration along the path).
2. **Speed profile (look-ahead).** The path speed sdot(s) is the largest profile that starts and ends at
   rest and keeps, at every sample,
   sdot <= v (the speed command), |q_j'(s)| sdot <= vmax_j (axis speeds),
   |q_j''(s)| sdot^2 <= (1 - beta) amax_j and kappa(s) sdot^2 <= a_tcp (centripetal: axis accelerations and
   the controller's TCP acceleration), and changes with path acceleration at most
   min(a_tcp, beta amax_j / |q_j'(s)|) (tangential). It is computed by one forward and one backward pass,
   each a running minimum over sdot^2 (vectorised, no loop).
3. **Jerk.** s(t), sampled at ``rate``, is smoothed by a moving average over ``fir_window`` s (an FIR filter
   on the path parameter, as CNC interpolators do): the path is unchanged, acceleration becomes continuous
   and the path jerk is at most (path acceleration) / ``fir_window``. Near slow-downs the filtered speed
   may exceed the look-ahead limit briefly, as a real controller's does.
4. **Servo.** Each axis follows its setpoint q_ref(t) = q(s(t)) through a second-order lag
   (omega_n^2 + ff 2 zeta omega_n s) / (s^2 + 2 zeta omega_n s + omega_n^2), omega_n = 2 pi ``servo_hz``
   (bilinear discretisation at ``rate``), ``ff`` the share of velocity feed-forward. On a curve of radius R at
   speed v the executed path cuts inside by about v^2 / (R omega_n^2) without feed-forward (less with it):
   the speed- and curvature-dependent error of a real arm. After the last setpoint the servo settles for ``settle_s``.
5. **Measurement.** TCP pose by forward kinematics of the executed joints; optional Gaussian noise of
   ``noise_mm`` on the positions, drawn from ``numpy.random.default_rng(seed)`` (deterministic by seed);
   ``runs`` > 1 averages that many noisy runs (the paper averages 5 runs on the real robot).

A straight MoveL stays on its line up to the servo's second-order terms (the lag acts on the joints, whose
path is curved even when the TCP's is straight): measured 0.002 / 0.04 / 0.6 mm off a 500 mm line at
50 / 200 / 800 mm/s. A corner cuts by the blend's r sin(theta / 2) / 2 (from the waypoint) plus the servo's
share, which grows with speed.
**Two models** share this interface, chosen by ``ControllerParams.model``: ``"lag"`` (the default, the one described
above, which the shipped tables and policies were made with) and ``"abb"``, the model calibrated to a recorded
ABB controller (docs/industrial.md): the queue planner of :mod:`pathrl.industrial.planner` (finite look-ahead, zones
that shrink or degrade to fine points with a reported corner event, orientation blended across zones,
speed-dependent corner cut), the rigid-body dynamics of :mod:`pathrl.industrial.dynamics` (PyBullet) under the
elastic, frictional, torque-limited drives and cascaded servo loops of :mod:`pathrl.industrial.drives`, and
execution variation (start jitter, friction change, slow drift, noise), all seeded by ``seed``.

The numbers in :class:`ControllerParams` are model choices (servo bandwidth, TCP acceleration), chosen so
the 100-MoveL baseline errors land in the paper's range; the axis limits are the IRB 6640 datasheet's
(:mod:`pathrl.industrial.arm`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.signal import bilinear, lfilter

from pathrl.industrial import arm
from pathrl.industrial.drives import DriveParams
from pathrl.industrial.planner import CornerEvent, PlannerParams, lookahead
from pathrl.industrial.program import PathSamples, Program, sample_path

__all__ = ["ControllerParams", "Execution", "execute", "servo", "speed_limit", "time_law"]


@dataclass(frozen=True)
class ControllerParams:
    """Controller model parameters (units in the field comments)."""

    rate: float = 250.0  # Hz, setpoint and measurement rate
    step_mm: float = 0.5  # mm, geometric path sampling
    tcp_acc: float = 8000.0  # mm/s^2, TCP path acceleration (tangential and centripetal)
    beta: float = 0.5  # share of the axis acceleration budget for the tangential part
    fir_window: float = 0.04  # s, moving average of s(t) (jerk limit)
    servo_hz: float = 4.0  # Hz, servo natural frequency omega_n / (2 pi)
    zeta: float = 1.0  # servo damping ratio
    ff: float = 0.0  # share of velocity feed-forward in the servo
    settle_s: float = 0.3  # s, servo settling after the last setpoint
    noise_mm: float = 0.0  # mm, std of the measurement noise on TCP positions
    runs: int = 1  # noisy runs averaged
    model: str = "lag"  # "lag" (this module's servo lag) or "abb" (the model calibrated to a recorded controller)
    planner: PlannerParams = field(default_factory=PlannerParams)  # "abb": the path planner
    drives: DriveParams = field(default_factory=DriveParams)  # "abb": drives, servo, execution variation

    def __post_init__(self) -> None:
        for key, cls in (("planner", PlannerParams), ("drives", DriveParams)):
            value: Any = getattr(self, key)
            if isinstance(value, dict):
                object.__setattr__(self, key, cls(**value))
        if self.model not in ("lag", "abb"):
            raise ValueError(f"controller.model must be 'lag' or 'abb', got {self.model!r}")
        for key in ("rate", "step_mm", "tcp_acc", "servo_hz", "zeta"):
            if not getattr(self, key) > 0.0:
                raise ValueError(f"controller.{key} must be > 0, got {getattr(self, key)}")
        if not (0.0 < self.beta < 1.0 and 0.0 <= self.ff <= 1.0 and self.runs >= 1 and self.noise_mm >= 0.0):
            raise ValueError("controller: need 0 < beta < 1, 0 <= ff <= 1, runs >= 1, noise_mm >= 0")


@dataclass(frozen=True)
class Execution:
    """An executed program: times t (n,) s, TCP positions p (n, 3) mm, tool rotations rot (n, 3, 3), executed
    joints q (n, 6) rad, joint setpoints q_ref (n, 6) and the planned path speed sdot (n,) mm/s."""

    t: np.ndarray
    p: np.ndarray
    rot: np.ndarray
    q: np.ndarray
    q_ref: np.ndarray
    sdot: np.ndarray
    events: tuple[CornerEvent, ...] = ()


def speed_limit(path: PathSamples, v: float, params: ControllerParams) -> tuple[np.ndarray, np.ndarray]:
    """Pointwise bounds along the path: the largest sdot^2 (K,) (mm/s)^2 and the tangential path
    acceleration (K,) mm/s^2 (see the module doc, step 2)."""
    qs = np.gradient(path.q, path.s, axis=0)
    qss = np.gradient(qs, path.s, axis=0)
    kappa = np.linalg.norm(np.gradient(np.gradient(path.p, path.s, axis=0), path.s, axis=0), axis=1)
    tiny = 1e-12
    w = np.full(len(path.s), float(v) ** 2)
    w = np.minimum(w, np.min((arm.VEL_LIMITS / np.maximum(np.abs(qs), tiny)) ** 2, axis=1))
    w = np.minimum(w, np.min((1 - params.beta) * arm.ACC_LIMITS / np.maximum(np.abs(qss), tiny), axis=1))
    w = np.minimum(w, params.tcp_acc / np.maximum(kappa, tiny))
    acc = np.minimum(params.tcp_acc, np.min(params.beta * arm.ACC_LIMITS / np.maximum(np.abs(qs), tiny), axis=1))
    return w, acc


def time_law(s: np.ndarray, sdot: np.ndarray, params: ControllerParams) -> np.ndarray:
    """Path parameter s(t) at the control rate (n,), FIR-smoothed (module doc, step 3)."""
    dt = 2.0 * np.diff(s) / np.maximum(sdot[:-1] + sdot[1:], 1e-9)
    t = np.r_[0.0, np.cumsum(dt)]
    grid = np.arange(0.0, t[-1] + 1.0 / params.rate, 1.0 / params.rate)
    st = np.interp(grid, t, s)
    n = max(int(round(params.fir_window * params.rate)), 1)
    if n > 1:
        padded = np.r_[np.full(n - 1, st[0]), st, np.full(n - 1, st[-1])]
        st = np.convolve(padded, np.ones(n) / n, mode="valid")
    return st


def servo(q_ref: np.ndarray, params: ControllerParams) -> np.ndarray:
    """Executed joints (n, 6): each axis of the setpoints (n, 6) through the second-order lag (module doc)."""
    wn, z = 2 * np.pi * params.servo_hz, params.zeta
    b, a = bilinear([params.ff * 2 * z * wn, wn**2], [1.0, 2 * z * wn, wn**2], fs=params.rate)
    return q_ref[0] + lfilter(b, a, q_ref - q_ref[0], axis=0)


def execute(program: Program, v: float, params: ControllerParams | None = None, seed: int = 0) -> Execution:
    """Run `program` at speed command `v` mm/s on the simulated controller (module doc)."""
    params = ControllerParams() if params is None else params
    if not v > 0.0:
        raise ValueError(f"speed command must be > 0 mm/s, got {v}")
    if params.model == "abb":
        return _execute_abb(program, v, params, seed)
    path = sample_path(program, params.step_mm)
    if not arm.within_limits(path.q).all():
        raise ValueError("the program's path leaves the IRB 6640 axis ranges")
    w_max, acc = speed_limit(path, v, params)
    sdot = lookahead(path.s, w_max, acc)
    st = time_law(path.s, sdot, params)
    st = np.r_[st, np.full(int(round(params.settle_s * params.rate)), st[-1])]
    q_ref = np.stack([np.interp(st, path.s, path.q[:, j]) for j in range(6)], axis=1)
    q = servo(q_ref, params)
    p, rot = arm.fk(q)
    if params.noise_mm > 0.0:
        rng = np.random.default_rng(seed)
        p = p + rng.normal(0.0, params.noise_mm, (params.runs, *p.shape)).mean(axis=0)
    t = np.arange(len(st)) / params.rate
    return Execution(t, p, rot, q, q_ref, np.gradient(st, t))


def _drift(t: np.ndarray, amplitude: float, rng: np.random.Generator) -> np.ndarray:
    """A slow TCP drift (n, 3) mm over times t (n,) s: random direction, sinusoid of random period 20-60 s and
    phase (thermal growth between and during executions)."""
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    period, phase = rng.uniform(20.0, 60.0), rng.uniform(0.0, 2.0 * np.pi)
    return amplitude * np.sin(2.0 * np.pi * t / period + phase)[:, None] * direction


def _execute_abb(program: Program, v: float, params: ControllerParams, seed: int) -> Execution:
    """The calibrated model (module doc): plan, drives, forward kinematics, variation."""
    from pathrl.industrial import drives, dynamics, planner

    tool = arm.DEFAULT_TOOL if program.tool is None else program.tool
    pl = planner.plan(program, v, params.planner, tool, params.rate, params.settle_s)
    true = dynamics.cached(dynamics.nominal())
    model = dynamics.cached(dynamics.perturbed(dynamics.nominal(), params.drives.model_error, params.drives.model_seed))
    k_gear, d_gear = drives.gear_matrices(true.mass_matrix(drives.NOMINAL_Q[None])[0], params.drives)
    rng = np.random.default_rng(seed)
    q = drives.simulate(pl.q, params.rate, true, model, k_gear, d_gear, params.drives, rng)
    p, rot = arm.fk(q, tool.offset)
    rot = rot @ tool.rot
    p = p + _drift(pl.t, params.drives.drift_mm, rng)
    noise = params.drives.noise_mm + params.noise_mm
    if noise > 0.0:
        p = p + rng.normal(0.0, noise, (params.runs, *p.shape)).mean(axis=0)
    return Execution(pl.t, p, rot, q, pl.q, pl.sdot, pl.events)
