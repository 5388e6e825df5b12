"""How much does a ball policy tilt its plate, and does its path deviation follow the tilt? (analytic ball)

Runs the policy of each run directory deterministically on the 200 whole ball-balancing test paths, as
``pathrl-eval ... backend=analytic`` does, and reports per policy, up to the end of the path:

* the mean plate tilt (angle of the plate's normal to world z, from the commanded 240 Hz setpoints);
* the tilt a ball at rest on the plate would need: atan(|horizontal plate acceleration| / g), the acceleration
  from second differences of the plate centre, averaged over 0.1 s;
* the correlation over episodes of the mean Cartesian deviation (TCP, matched samples as in metrics.json) with
  the mean tilt.

Usage:
    .venv/bin/python tools/lab/plate_tilt.py models/tracking/iiwa7_ball_balancing_reward_scratch_deviation [...]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from pathrl.eval.evaluate import EvalOptions, run_rollouts
from pathrl.eval.metrics import matched_samples, sample_deviations
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.sim.feedback import GRAVITY, plate_pose

DATASET = "datasets/iiwa7/ball_balancing"
STEP = 24  # setpoints per 0.1 s decision step
SMOOTH = 12  # setpoints averaged for the plate acceleration (0.05 s each side)


def tilt_and_need(fk: ForwardKinematics, setpoints: Tensor, rate: float = 240.0) -> tuple[float, float]:
    """Mean plate tilt and mean tilt a resting ball would need (rad) over setpoints (S, D) (rad)."""
    o, r = plate_pose(fk, setpoints.to(torch.float64))
    tilt = torch.arccos(r[:, 2, 2].clamp(-1.0, 1.0))
    acc = (o[2:] - 2.0 * o[1:-1] + o[:-2]) * rate**2
    acc = torch.nn.functional.avg_pool1d(acc.T.unsqueeze(0), SMOOTH, 1).squeeze(0).T
    need = torch.atan(acc[:, :2].norm(dim=1) / GRAVITY)
    return tilt.mean().item(), need.mean().item()


def analyse(run_dir: Path) -> dict[str, float]:
    """Duration to the end of the path (s), deviation (cm), tilt, needed tilt (deg) and their correlation."""
    opts = EvalOptions(dataset_path=DATASET, segments="full", backend="analytic", record=False, progress=False)
    records, _, src = run_rollouts(run_dir, opts)
    fk, index = src.env.fk, torch.as_tensor(src.robot.path_index)
    matched = matched_samples([r.setpoints for r in records], index, src.paths, [r.path for r in records],
                              [r.start_s for r in records], [r.end_s for r in records])
    devs = sample_deviations([r.setpoints for r in records], matched, index, fk)  # as metrics.json has them
    rows = []
    for rec, dev in zip(records, devs, strict=True):
        n = rec.finish_step * STEP if rec.finish_step >= 0 else len(rec.setpoints) - 1
        tilt, need = tilt_and_need(fk, rec.setpoints[: n + 1])
        rows.append((tilt, need, dev["cart_pos_dev_mean_cm"], rec.finish_step * 0.1))
    a = np.array(rows)
    return {"end_of_path_s": float(a[:, 3].mean()), "deviation_cm": float(a[:, 2].mean()),
            "tilt_deg": math.degrees(a[:, 0].mean()), "needed_tilt_deg": math.degrees(a[:, 1].mean()),
            "corr_deviation_tilt": float(np.corrcoef(a[:, 2], a[:, 0])[0, 1])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dirs", nargs="+", type=Path)
    for run_dir in parser.parse_args().run_dirs:
        m = analyse(run_dir)
        print(f"{run_dir}: end of path {m['end_of_path_s']:.2f} s, deviation {m['deviation_cm']:.2f} cm, "
              f"tilt {m['tilt_deg']:.2f} deg, a resting ball needs {m['needed_tilt_deg']:.2f} deg, "
              f"corr(deviation, tilt) {m['corr_deviation_tilt']:.2f}")


if __name__ == "__main__":
    main()
