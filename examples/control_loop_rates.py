"""A robot's control loop at 100 Hz or 500 Hz around a shipped policy: setpoints at the loop's rate, a measured
position fed back every decision, the path ending on its last waypoint at rest.

    .venv/bin/python examples/control_loop_rates.py [100|500] [models/tracking/iiwa7_random] [datasets/iiwa7/random]

Every 0.1 s the follower decides and returns the next 0.1 s of setpoints at the loop's rate (10 at 100 Hz, 50 at
500 Hz): the env's trajectory sampled exactly at that rate. Here a stand-in robot tracks them with a small lag
(its measured position is the setpoint of one tick earlier); `decide(q_measured=...)` compares it with the
commanded position and refuses to go on beyond 0.05 rad. At the path's end the follower moves onto the last
waypoint with a jerk-limited final approach; `done` once at rest there within 0.005 rad.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import torch

from pathrl.dataset.io import load_dataset
from pathrl.deploy import Follower
from pathrl.limits.check import limit_violations
from pathrl.limits.feasible import JointLimits


def main(rate: str = "500", model: str = "models/tracking/iiwa7_random",
         dataset: str = "datasets/iiwa7/random") -> None:
    rate_hz = float(rate)
    follower = Follower.load(model, control_rate=rate_hz)
    knots = load_dataset(dataset, follower.robot).splits["test"].knots[0]
    follower.reset(knots)
    measured = follower.state[0]  # the stand-in robot: at the last setpoint sent one tick ago
    sent, lat, lag = [], [], []
    while not follower.done and len(lat) < 600:
        t0 = time.perf_counter()
        sp = follower.decide(q_measured=measured)
        lat.append(time.perf_counter() - t0)
        lag.append(follower.measured_error)
        for k in range(len(sp.position)):  # one tick each: here the setpoint goes to the robot
            sent.append((sp.position[k], sp.velocity[k], sp.acceleration[k]))
            measured = sent[-2][0] if len(sent) > 1 else sent[-1][0]
    p, v, a = (torch.as_tensor(np.array(x))[None] for x in zip(*sent, strict=True))
    bad = int(limit_violations(p, v, a, JointLimits.from_robot(follower.robot), 1.0 / rate_hz)["total"][0])
    lat_ms = 1e3 * np.asarray(lat)
    print(f"{rate_hz:g} Hz: {len(sent)} setpoints ({follower.setpoints_per_decision} per decision), at rest on the "
          f"last waypoint after {len(lat) * 0.1:.1f} s: error {follower.final_error:.1e} rad (largest joint), "
          f"final approach {follower.final_approach_s:.2f} s, {bad} limit violations; measured lag up to "
          f"{max(lag):.4f} rad; decision latency mean {lat_ms.mean():.2f} ms, max {lat_ms.max():.2f} ms")


if __name__ == "__main__":
    main(*sys.argv[1:])
