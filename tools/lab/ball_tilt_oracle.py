"""How hard is the ball on the plate? A model-based check on the ball-balancing test paths (analytic ball).

Each test path is run whole with a minimum-jerk time law of duration T (s(t) = L (10 u^3 - 15 u^4 + 6 u^5),
u = t / T, 240 Hz setpoints; joint limits are not checked), then held for 2 s, in two ways:

* level: the reference itself (the paths keep the plate level);
* tilted: the reference corrected, per setpoint, so that the plate's normal points along a - g (a: the
  plate's acceleration, smoothed over +-50 ms), a waiter's tray. The correction dq solves the damped
  least-squares problem  min |J_o dq - (o_ref - o)|^2 + |E J_n dq - E (n_d - n)|^2 + lam |dq|^2  (o: plate
  origin, n: plate normal, E: the plate's x and y axes; the turn about the normal is left free; Jacobians by
  finite differences), repeated `--iters` times.

Prints the share of balls lost and the joint / TCP deviation of the correction. Usage:
    .venv/bin/python tools/lab/ball_tilt_oracle.py --durations 3 6 [--iters 1] [--lam 1e-3]
"""

from __future__ import annotations

import argparse

import torch
from torch import Tensor

from pathrl.dataset.io import load_pathset
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.sim.feedback import GRAVITY, AnalyticBall, plate_pose

RATE = 240.0
STEP = 24  # setpoints per 0.1 s decision step


def min_jerk(n: int) -> Tensor:
    """Normalized arc length (n + 1,) of a rest-to-rest minimum-jerk time law."""
    u = torch.linspace(0.0, 1.0, n + 1, dtype=torch.float64)
    return 10 * u**3 - 15 * u**4 + 6 * u**5


def moving_average(x: Tensor, k: int) -> Tensor:
    """Centred moving average of (P, S, 3) over +-k samples, edges held."""
    pad = torch.cat([x[:, :1].expand(-1, k, -1), x, x[:, -1:].expand(-1, k, -1)], 1)
    c = torch.cat([torch.zeros_like(pad[:, :1]), pad.cumsum(1)], 1)
    return (c[:, 2 * k + 1:] - c[:, : -2 * k - 1]) / (2 * k + 1)


def tilt_correction(fk: ForwardKinematics, q: Tensor, iters: int, lam: float, smooth: int = 12) -> Tensor:
    """Joint trajectories (P, S, 7) corrected so the plate tilts into its acceleration (module docstring)."""
    g = torch.tensor([0.0, 0.0, -GRAVITY], dtype=torch.float64)
    h = 1.0 / RATE
    o_ref, _ = plate_pose(fk, q)
    qc = q.clone()
    for _ in range(iters):
        o, r = plate_pose(fk, qc)
        n = r[..., :, 2]
        a = torch.zeros_like(o)
        a[:, 1:-1] = (o[:, 2:] - 2 * o[:, 1:-1] + o[:, :-2]) / h**2
        nd = moving_average(a, smooth) - g
        nd = nd / nd.norm(dim=-1, keepdim=True)
        cols = []
        for j in range(q.shape[-1]):
            dq = torch.zeros(q.shape[-1], dtype=torch.float64)
            dq[j] = 1e-6
            oj, rj = plate_pose(fk, qc + dq)
            cols.append(torch.cat([oj - o, rj[..., :, 2] - n], -1) / 1e-6)
        jac = torch.stack(cols, -1)  # (P, S, 6, D)
        e = torch.stack([r[..., :, 0], r[..., :, 1]], -2)  # (P, S, 2, 3)
        a_mat = torch.cat([jac[..., :3, :], e @ jac[..., 3:, :]], -2)
        b = torch.cat([o_ref - o, (e @ (nd - n).unsqueeze(-1)).squeeze(-1)], -1)
        hess = a_mat.transpose(-1, -2) @ a_mat + lam * torch.eye(q.shape[-1], dtype=torch.float64)
        qc = qc + torch.linalg.solve(hess, a_mat.transpose(-1, -2) @ b.unsqueeze(-1)).squeeze(-1)
    return qc


def balls_lost(robot, q: Tensor, hold_steps: int = 20) -> float:
    """Share (%) of balls (one per trajectory, drawn as in training) off the plate after q (P, S, D) and a hold."""
    p = q.shape[0]
    ball = AnalyticBall(robot, p, seed=0)
    ids = torch.arange(p)
    ball.reset(ids, q[:, 0])
    for k in range(0, q.shape[1] - 1, STEP):
        chunk = q[:, k + 1:k + 1 + STEP]
        if chunk.shape[1] < STEP:
            chunk = torch.cat([chunk, chunk[:, -1:].expand(p, STEP - chunk.shape[1], -1)], 1)
        ball.step(chunk, None)
    for _ in range(hold_steps):
        ball.step(q[:, -1:].expand(p, STEP, -1), None)
    return 100.0 * (1.0 - float(ball.on.double().mean()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", default="datasets/iiwa7/ball_balancing")
    ap.add_argument("--durations", type=float, nargs="+", default=[3.0, 6.0])
    ap.add_argument("--iters", type=int, default=1)
    ap.add_argument("--lam", type=float, default=1e-3)
    args = ap.parse_args()
    torch.set_num_threads(1)
    robot = load_robot_by_name("iiwa7")
    paths = load_pathset(args.dataset, "test", KnotStrategy("distance", 0.3, 0.1, 5), robot)
    fk = ForwardKinematics(robot)
    ids = torch.arange(len(paths.length))
    for duration in args.durations:
        s = paths.length.unsqueeze(1) * min_jerk(int(round(duration * RATE)))
        q = paths.position_at(ids, s)
        qc = tilt_correction(fk, q, args.iters, args.lam)
        dev = (qc - q).norm(dim=-1)
        flat = q.reshape(-1, q.shape[-1])
        tcp = (fk.tcp_positions(qc.reshape(flat.shape)) - fk.tcp_positions(flat)).norm(dim=-1)
        print(f"T = {duration:4.1f} s, {len(ids)} paths: level plate lost {balls_lost(robot, q):5.1f} %, tilted "
              f"{balls_lost(robot, qc):5.1f} % (joint correction mean {float(dev.mean()):.3f} rad, 95th pct "
              f"{float(dev.quantile(0.95)):.3f} rad; TCP mean {100 * float(tcp.mean()):.1f} cm)")


if __name__ == "__main__":
    main()
