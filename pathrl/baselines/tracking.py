"""Acting through the env's action like a policy: the tracking law and the inverse action mapping that the
model-based controllers (:mod:`pathrl.baselines.ball_feedback`, :mod:`pathrl.baselines.greedy_follower`) share."""

from __future__ import annotations

from torch import Tensor

__all__ = ["linear_action", "tracking_acceleration"]


def tracking_acceleration(pos: Tensor, vel: Tensor, acc: Tensor, q_d: Tensor, v_d: Tensor, a_d: Tensor, dt: float,
                          omega: float) -> Tensor:
    """End-of-step acceleration (N, D) of the implicit critically damped law on the end-of-step state:
    ``a1 = a_d + kq (q_d - q1(a1)) + kv (v_d - v1(a1))`` with ``q1 = A_q + dt^2/6 a1``, ``v1 = A_v + dt/2 a1``
    (linearly interpolated acceleration), kq = omega^2, kv = 2 omega; all (N, D)."""
    a_q = pos + vel * dt + acc * (dt * dt / 3.0)
    a_v = vel + acc * (dt / 2.0)
    kq, kv = omega * omega, 2.0 * omega
    return (a_d + kq * (q_d - a_q) + kv * (v_d - a_v)) / (1.0 + kq * dt * dt / 6.0 + kv * dt / 2.0)


def linear_action(acc: Tensor, a_min: Tensor, a_max: Tensor) -> Tensor:
    """Inverse of the env's linear action mapping: the action in [-1, 1] whose acceleration is `acc` clipped
    into ``[a_min, a_max]``; all (N, D)."""
    span = (a_max - a_min).clamp(min=1e-12)
    return (2.0 * (acc - a_min) / span - 1.0).clamp(-1.0, 1.0)
