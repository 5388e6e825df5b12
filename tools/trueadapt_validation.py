"""TrueAdapt Sec. VI-D: limit validation with random / maximal accelerations from the valid range, and plots.

    .venv/bin/python tools/trueadapt_validation.py --trajectories 100000 --steps 100
    .venv/bin/python tools/trueadapt_validation.py --trajectories 0 --plot docs/trueadapt_validation.png
    .venv/bin/python tools/trueadapt_validation.py --out results/raw/trueadapt_validation.json   # also as JSON

Prints the violation counts of both modes as JSON; ``--plot`` draws one trajectory per mode (joint ``--joint``:
position, velocity, acceleration, jerk against their limits), like the paper's Figs. 5 (maximum) and 6 (random).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import torch

from pathrl.cli.common import ArgParser, UserError, output_file, run_cli
from pathrl.eval.trueadapt_validation import MODES, trace, validate
from pathrl.limits.feasible import JointLimits
from pathrl.robot.external import load_robot_by_name


def plot(limits: JointLimits, joint: int, steps: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pathrl.storage import atomic_write

    fig, axes = plt.subplots(4, 2, figsize=(10, 8), sharex=True)
    start = torch.zeros(limits.dof, dtype=torch.float64)
    start[joint] = limits.pos[joint, 0] + 0.3 * (limits.pos[joint, 1] - limits.pos[joint, 0])
    rows = (("p", "position (rad)", limits.pos[joint]), ("v", "velocity (rad/s)", limits.vel[joint]),
            ("a", "acceleration (rad/s²)", limits.acc[joint]), ("j", "jerk (rad/s³)", limits.jerk[joint]))
    for col, mode in enumerate(("max", "random")):
        tr = trace(limits, steps, mode=mode, seed=1, start=start)
        for row, (key, label, lim) in enumerate(rows):
            ax = axes[row, col]
            ax.plot(tr["t"], tr[key][:, joint], lw=1.2)
            for bound in (lim.tolist() if lim.ndim else [-float(lim), float(lim)]):
                ax.axhline(bound, color="r", ls="--", lw=0.8)
            ax.set_ylabel(label if col == 0 else "")
        axes[0, col].set_title("maximum acceleration every step" if mode == "max" else "random accelerations")
        axes[-1, col].set_xlabel("time (s)")
    fig.suptitle(f"iiwa7 joint {joint + 1}: accelerations from the valid range (dt = 50 ms, 240 Hz samples)")
    fig.tight_layout()
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110))
    plt.close(fig)


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The command line, checked (UserError: one line): counts in range, ``--plot`` / ``--out`` writable, before
    any work."""
    ap = ArgParser(prog="trueadapt_validation.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--trajectories", type=int, default=100_000)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--joint", type=int, default=0, help="joint index for the plot")
    ap.add_argument("--plot", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=None, help="also write the results to this JSON file")
    args = ap.parse_args(argv)
    if args.trajectories < 0:
        raise UserError(f"--trajectories must be >= 0, got {args.trajectories}")
    if args.steps < 1:
        raise UserError(f"--steps must be >= 1, got {args.steps}")
    if args.trajectories == 0 and args.plot is None:
        raise UserError("nothing to do: --trajectories 0 without --plot")
    if args.trajectories == 0 and args.out is not None:
        raise UserError("--out needs --trajectories >= 1 (it records the validation's counts)")
    for flag, path in (("--plot", args.plot), ("--out", args.out)):
        if path is not None:
            output_file(path, flag)
    return args


def _main(argv: list[str]) -> None:
    args = parse_args(argv)
    torch.set_num_threads(1)
    limits = JointLimits.from_robot(load_robot_by_name("iiwa7"))
    if not 0 <= args.joint < limits.dof:
        raise UserError(f"--joint must be in 0..{limits.dof - 1} (iiwa7), got {args.joint}")
    if args.plot is not None:
        args.plot.parent.mkdir(parents=True, exist_ok=True)
        plot(limits, args.joint, args.steps, args.plot)
    if args.trajectories > 0:
        out = [asdict(validate(limits, args.trajectories, args.steps, mode=m, seed=args.seed)) for m in MODES]
        print(json.dumps(out, indent=1))
        if args.out is not None:
            from pathrl.storage import write_json_atomic

            args.out.parent.mkdir(parents=True, exist_ok=True)
            write_json_atomic(args.out, out)


def main(argv: list[str] | None = None) -> int:
    """Entry point (argv: sys.argv[1:]); 0, or 2 with a one-line error on stderr."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
