"""Drive train and servo of the calibrated controller model: elastic gears, friction, torque limits and cascaded
position / velocity loops with feed-forward from a deliberately wrong model.

Per axis j (link side, gear ratio folded in: motor angle theta and its inertia B_j are reflected to the link):

    link   M(q) qdd + h(q, qd) = tau_s,            tau_s = K (theta - q) + D (thetad - qd)
    motor  B thetadd = tau_m - tau_s - f(thetad),  f = F_c tanh(thetad / 0.01) + F_v thetad
    servo  (motor encoder) v_c = k_p (theta_r - theta) + ff_vel thetad_r
           tau_m = clip(k_v (v_c - thetad) + (k_v / t_i) int (v_c - thetad) + tau_ff, +-tau_max)

M and h (Coriolis, centrifugal, gravity) come from PyBullet (:mod:`pathrl.industrial.dynamics`), evaluated along
the planned setpoints (the executed joints stay within ~1e-3 rad of them, where M and h change by < 1e-3
relatively: a linearisation around the plan that keeps the loop cheap). The controller knows only its own
model (M^, h^, friction F^ = (1 - ``friction_error``) F): it commands the motor to theta_r = q_r + tau^_s / K
(the gear deflection its model predicts, compensated) and feeds forward
tau_ff = ``ff_torque`` (M^(q_r) qdd_r + B thetadd_r) + h^(q_r, qd_r) + f^(thetad_r): the bias and friction
torques in full, a share of the inertial ones.

Parameter sources (all per axis 1-6; *estimated* = no public figure, chosen for a 1.4 t, 2.55 m arm):

* ``gear_hz``: locked-motor natural frequency of each link on its gear at the calibration start pose (K_j =
  M_jj (2 pi f_j)^2), *estimated* from the 8-15 Hz first modes reported for 150-250 kg payload arms, and
  ``gear_zeta`` the gears' structural damping (D_j = 2 zeta M_jj 2 pi f_j), *estimated*;
* ``rotor_inertia``: reflected motor inertia B_j (kg m^2) = rotor inertia x gear ratio^2, *estimated* (ratios
  ~200 on axes 1-3, ~100 on the wrist; rotors 0.5-6e-3 kg m^2);
* ``coulomb`` / ``viscous``: joint friction (N m, N m s/rad), *estimated* at 2-4 % of ``torque_max``;
* ``torque_max``: link-side torque limits, *estimated* from the 180 kg payload's static and dynamic load;
* ``kp`` / ``vel_hz`` / ``ti_s``: servo tuning (1/s, Hz, s), *chosen* (typical industrial values), velocity
  loop gain k_v = (B_j + M_jj) 2 pi ``vel_hz``; ``ff_vel`` / ``ff_torque`` the feed-forward shares;
* ``model_error``: the feed-forward model's masses / centres of mass are off by up to this share (seeded by
  ``model_seed``, one fixed wrong model per controller; *calibrated* on the curve-1 recording,
  ``docs/industrial.md``), ``friction_error`` its friction underestimate.

Execution variation (seeded by the execution's seed): a start delay uniform in [0, ``start_jitter_s``]; a
run-to-run friction scale 1 + ``friction_var`` N(0, 1); a slow drift of the TCP (thermal growth, random
direction, amplitude ``drift_mm`` reached as 1 - cos over a random 20-60 s period); white measurement noise
``noise_mm``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pathrl.industrial.dynamics import Dynamics

__all__ = ["NOMINAL_Q", "DriveParams", "drive_loop", "drive_loop_python", "gear_matrices", "gear_step",
           "simulate"]

#: The pose whose mass matrix sets the gear stiffness (the curve-1 recording's start configuration, rad).
NOMINAL_Q = np.array([-0.58589046, -0.03341733, 0.40482559, -2.79157683, -1.61501501, 0.95669868])


@dataclass(frozen=True)
class DriveParams:
    """Drive and servo parameters (module doc for their sources)."""

    sim_hz: float = 1000.0  # Hz, integration rate of the drive model
    kp: list[float] = field(default_factory=lambda: [30.0, 30.0, 30.0, 30.0, 30.0, 30.0])  # 1/s, position loops
    vel_hz: float = 20.0  # Hz, velocity loop bandwidth
    ti_s: float = 0.05  # s, velocity loop integral time
    ff_vel: float = 1.0  # share of velocity feed-forward
    ff_torque: float = 1.0  # share of the inertial torque fed forward (gravity, Coriolis, friction: always)
    gear_hz: list[float] = field(default_factory=lambda: [9.0, 9.0, 12.0, 18.0, 18.0, 25.0])
    gear_zeta: float = 0.05
    rotor_inertia: list[float] = field(default_factory=lambda: [240.0, 240.0, 160.0, 10.0, 10.0, 5.0])
    coulomb: list[float] = field(default_factory=lambda: [200.0, 250.0, 150.0, 30.0, 30.0, 15.0])
    viscous: list[float] = field(default_factory=lambda: [400.0, 500.0, 300.0, 40.0, 40.0, 20.0])
    torque_max: list[float] = field(default_factory=lambda: [7000.0, 12000.0, 7000.0, 1500.0, 1500.0, 800.0])
    model_error: float = 0.01
    model_seed: int = 6640
    friction_error: float = 0.2
    start_jitter_s: float = 0.004
    friction_var: float = 0.05
    drift_mm: float = 0.01
    noise_mm: float = 0.0

    def __post_init__(self) -> None:
        for key in ("sim_hz", "vel_hz", "ti_s"):
            if not getattr(self, key) > 0.0:
                raise ValueError(f"drives.{key} must be > 0, got {getattr(self, key)}")
        for key in ("kp", "gear_hz", "rotor_inertia", "coulomb", "viscous", "torque_max"):
            vals = getattr(self, key)
            if len(vals) != 6 or min(vals) < 0.0 or (key in ("gear_hz", "rotor_inertia", "torque_max")
                                                     and min(vals) <= 0.0):
                raise ValueError(f"drives.{key} needs 6 values (> 0), got {vals}")
        if min(self.kp) <= 0.0:
            raise ValueError(f"drives.kp must be > 0 on every axis, got {self.kp}")
        if min(self.model_error, self.friction_error, self.start_jitter_s, self.friction_var, self.drift_mm,
               self.noise_mm, self.gear_zeta, self.ff_vel, self.ff_torque) < 0.0:
            raise ValueError("drives: errors, variations, damping and feed-forward shares must be >= 0")


def gear_matrices(m_nominal: np.ndarray, params: DriveParams) -> tuple[np.ndarray, np.ndarray]:
    """Gear stiffness K (6,) N m/rad and damping D (6,) N m s/rad from the diagonal of the nominal mass matrix
    (6, 6) and the configured locked-motor frequencies and damping ratio."""
    w = 2.0 * np.pi * np.asarray(params.gear_hz)
    mjj = np.diag(m_nominal)
    return mjj * w**2, 2.0 * params.gear_zeta * mjj * w


def _resample(x: np.ndarray, n_out: int, factor: int) -> np.ndarray:
    """Linear interpolation of samples x (n, ...) at the plan rate onto n_out samples `factor` times denser."""
    src = np.arange(len(x)) * factor
    dst = np.arange(n_out)
    flat = x.reshape(len(x), -1)
    out = np.stack([np.interp(dst, src, flat[:, j]) for j in range(flat.shape[1])], axis=1)
    return out.reshape(n_out, *x.shape[1:])


def simulate(q_r: np.ndarray, rate: float, true: Dynamics, model: Dynamics, k_gear: np.ndarray, d_gear: np.ndarray,
             params: DriveParams, rng: np.random.Generator) -> np.ndarray:
    """Executed link angles (n, 6) rad at `rate` Hz of setpoints q_r (n, 6) at `rate` (module doc), integrated
    at ``sim_hz`` (semi-implicit Euler). `true` / `model` are the plant's and the controller's dynamics."""
    dt_p = 1.0 / rate
    factor = max(int(round(params.sim_hz / rate)), 1)
    dt = dt_p / factor
    delay = int(round(rng.uniform(0.0, params.start_jitter_s) / dt_p))
    q_r = np.r_[np.repeat(q_r[:1], delay, 0), q_r]
    qd_r = np.gradient(q_r, dt_p, axis=0)
    qdd_r = np.gradient(qd_r, dt_p, axis=0)
    sub = slice(None, None, 5)  # dynamics every 20 ms at 250 Hz, interpolated between (they vary slowly)
    idx = np.r_[np.arange(len(q_r))[sub], len(q_r) - 1]
    m_true = _resample_idx(true.mass_matrix(q_r[idx]), idx, len(q_r))
    h_true = _resample_idx(true.bias(q_r[idx], qd_r[idx]), idx, len(q_r))
    m_hat = _resample_idx(model.mass_matrix(q_r[idx]), idx, len(q_r))
    h_hat = _resample_idx(model.bias(q_r[idx], qd_r[idx]), idx, len(q_r))
    inertial = np.einsum("nij,nj->ni", m_hat, qdd_r)
    tau_hat = inertial + h_hat
    th_r = q_r + tau_hat / k_gear
    thd_r = np.gradient(th_r, dt_p, axis=0)
    thdd_r = np.gradient(thd_r, dt_p, axis=0)
    b = np.asarray(params.rotor_inertia)
    fc, fv = np.asarray(params.coulomb), np.asarray(params.viscous)
    f_scale = max(1.0 + params.friction_var * rng.normal(), 0.0)
    f_hat = (1.0 - params.friction_error) * (fc * np.tanh(thd_r / 0.01) + fv * thd_r)
    tau_ff = params.ff_torque * (inertial + b * thdd_r) + h_hat + f_hat
    n = (len(q_r) - 1) * factor + 1
    th_r_s, thd_r_s, tff_s, h_s = (_resample(x, n, factor) for x in (th_r, thd_r, tau_ff, h_true))
    minv = np.linalg.inv(m_true)
    minv_s = _resample(minv, n, factor)
    kv = (b + np.diagonal(m_true[0])) * 2.0 * np.pi * params.vel_hz
    ki = kv / params.ti_s
    tmax = np.asarray(params.torque_max)
    th, thd = th_r[0].copy(), np.zeros(6)
    q = th - h_true[0] / k_gear  # the link at rest on its gear, loaded by gravity
    qd = np.zeros(6)
    integ = (h_true[0] - tau_ff[0]) / ki  # the integrator holds what the feed-forward misses of gravity
    series = (th_r_s, thd_r_s, tff_s, h_s, minv_s)
    axes = (np.asarray(params.kp, dtype=float), kv, ki, tmax, k_gear, d_gear, b, fc, fv)
    out = drive_loop(series, axes, (th, thd, q, qd, integ), f_scale, params.ff_vel, dt)
    return out[::factor][delay:]


def drive_loop(series: tuple[np.ndarray, ...], axes: tuple[np.ndarray, ...], state: tuple[np.ndarray, ...],
               f_scale: float, ff_vel: float, dt: float) -> np.ndarray:
    """The drive-train loop of :func:`simulate` (arguments of :func:`drive_loop_python`): the native build
    (:func:`pathrl.native.drive_loop`) where available, else the Python reference (same results to rounding)."""
    from pathrl import native  # here, not at the top: it imports torch, which the controller does not need

    if native.available():
        return native.drive_loop(series, axes, state, f_scale, ff_vel, dt)
    return drive_loop_python(series, axes, state, f_scale, ff_vel, dt)


def drive_loop_python(series: tuple[np.ndarray, ...], axes: tuple[np.ndarray, ...], state: tuple[np.ndarray, ...],
                      f_scale: float, ff_vel: float, dt: float) -> np.ndarray:
    """Link angles (n, 6) rad after each semi-implicit Euler step of `dt` s of the drives and servos (module doc),
    the reference of ``pathrl/native/drives.c``. `series` (at the integration rate): motor setpoints th_r (n, 6),
    their rates thd_r (n, 6), feed-forward torques tau_ff (n, 6), the plant's bias torques h (n, 6) and inverse mass
    matrices (n, 6, 6); `axes` (6,) each: position gains kp, velocity gains kv, integral gains ki, torque limits,
    gear stiffness and damping, reflected rotor inertia b, Coulomb and viscous friction; `state` (6,) each: the
    initial motor angles th, rates thd, link angles q, rates qd and velocity-loop integrators (not modified);
    `f_scale` the run's friction scale, `ff_vel` the velocity feed-forward share."""
    th_r_s, thd_r_s, tff_s, h_s, minv_s = series
    kp, kv, ki, tmax, k_gear, d_gear, b, fc, fv = axes
    th, thd, q, qd, integ = (np.array(x, dtype=float) for x in state)
    out = np.empty((len(th_r_s), 6))
    for k in range(len(th_r_s)):
        ev = kp * (th_r_s[k] - th) + ff_vel * thd_r_s[k] - thd
        integ += ev * dt
        tau_m = np.clip(kv * ev + ki * integ + tff_s[k], -tmax, tmax)
        tau_s = k_gear * (th - q) + d_gear * (thd - qd)
        fr = f_scale * (fc * np.tanh(thd / 0.01) + fv * thd)
        thd = thd + dt * (tau_m - tau_s - fr) / b
        qd = qd + dt * (minv_s[k] @ (tau_s - h_s[k]))
        th = th + dt * thd
        q = q + dt * qd
        out[k] = q
    return out


def _resample_idx(x: np.ndarray, idx: np.ndarray, n: int) -> np.ndarray:
    """Values x (len(idx), ...) known at sample indices idx, linearly interpolated at 0..n-1."""
    flat = x.reshape(len(x), -1)
    out = np.stack([np.interp(np.arange(n), idx, flat[:, j]) for j in range(flat.shape[1])], axis=1)
    return out.reshape(n, *x.shape[1:])


def gear_step(m_jj: float, k: float, d: float, step: float, duration: float, dt: float = 1e-4) -> np.ndarray:
    """Link angle (n,) after the motor of one axis (link inertia m_jj kg m^2, gear k N m/rad, d N m s/rad) jumps
    by `step` rad and is held there (an ideal, infinitely stiff motor), integrated like :func:`simulate`."""
    n = int(round(duration / dt))
    q, qd = 0.0, 0.0
    out = np.empty(n)
    for i in range(n):
        qd += dt * (k * (step - q) - d * qd) / m_jj
        q += dt * qd
        out[i] = q
    return out
