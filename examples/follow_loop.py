"""A 10 Hz control loop around a shipped policy: follow one test path, switch to another one halfway.

    .venv/bin/python examples/follow_loop.py [models/tracking/iiwa7_random] [datasets/iiwa7/random]

Each decision returns the next 0.1 s of setpoints at 240 Hz (what a robot controller consumes); halfway along
the first path the follower is handed a new path that runs straight from where the robot is to the start of a
second test path and then along it (the robot keeps moving while the path changes).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from pathrl.dataset.io import load_dataset
from pathrl.deploy import Follower


def main(model: str = "models/tracking/iiwa7_random", dataset: str = "datasets/iiwa7/random") -> None:
    follower = Follower.load(model)
    paths = load_dataset(dataset, follower.robot).splits["test"].knots
    follower.reset(paths[0])
    half = follower.path_left / 2
    lat, speed, switched_at = [], [], None
    vel_limits = np.asarray(follower.robot.vel_limits)
    for k in range(600):  # at most 60 s
        t0 = time.perf_counter()
        sp = follower.decide()
        lat.append(time.perf_counter() - t0)
        speed.append(float(np.max(np.abs(sp.velocity) / vel_limits)))
        # ... here the setpoints go to the robot (sp.position, sp.velocity at 240 Hz) ...
        if switched_at is None and follower.path_left < half:
            q = follower.state[0]
            gap = follower.replace_path(np.vstack([q, paths[1]]))
            switched_at = (k + 1) * 0.1
            print(f"t = {switched_at:.1f} s: new path, {gap:.4f} rad from the robot, moving at "
                  f"{speed[-1]:.0%} of the velocity limit")
        if follower.done:
            break
    lat_ms = 1e3 * np.asarray(lat)
    print(f"at rest at the new path's end after {len(lat) * 0.1:.1f} s ({len(lat)} decisions); "
          f"highest velocity {max(speed):.0%} of its limit; decision latency mean {lat_ms.mean():.2f} ms, "
          f"max {lat_ms.max():.2f} ms")


if __name__ == "__main__":
    main(*sys.argv[1:])
