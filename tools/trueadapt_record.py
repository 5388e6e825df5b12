"""Record TrueAdapt adaptation episodes to DIR/trueadapt.mcap for ``pathrl-view DIR`` (reference vs adapted
trajectory, the ball on the plate).

    .venv/bin/python tools/trueadapt_record.py --controller reference --episodes 3 --out runs/trueadapt_view
    .venv/bin/python tools/trueadapt_record.py --run runs/iiwa7_trueadapt_on_plate/seed0 --out runs/trueadapt_view
    .venv/bin/python tools/trueadapt_record.py --controller reference --keep-going --task in_place --out DIR

The run (or the ``--task`` experiment's config without ``--run``), the env and the actor are loaded as
tools/trueadapt_eval.py loads them: a run's checkpoint (or the controller of its config.yaml), or ``--controller``
(a name such as ``reference`` or a YAML mapping ``{name: ..., <keys>}``). Trajectories 0 .. episodes-1 of the split,
deterministic actions, the analytic ball unless ``--backend pybullet``; ``--keep-going`` lets an episode run to the
end of its trajectory after the task failed (the joint-deviation termination stays).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from trueadapt_eval import load  # the sibling tool (tools/ is on the path of a script)

from pathrl.cli.common import ArgParser, UserError, output_dir, run_cli
from pathrl.eval.trueadapt_record import FILE_NAME, record_trueadapt


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line, checked (UserError: one line): ``--episodes`` >= 1, ``--out`` writable, before any work."""
    ap = ArgParser(prog="trueadapt_record.py", description=__doc__.split("\n\n")[0])
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--run", type=Path, default=None, help="a run or model directory (its checkpoint or controller)")
    src.add_argument("--controller", default=None, help="a controller name (e.g. reference) or YAML mapping")
    ap.add_argument("--task", choices=["on_plate", "in_place"], default="on_plate", help="without --run")
    ap.add_argument("--out", type=Path, required=True, help="output directory (gets trueadapt.mcap)")
    ap.add_argument("--episodes", type=int, default=3)
    ap.add_argument("--dataset", default=None, help="dataset directory (default: the config's)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--backend", choices=["analytic", "pybullet"], default="analytic", help="ball simulation")
    ap.add_argument("--checkpoint", type=Path, default=None, help="with --run: this checkpoint, not the latest")
    ap.add_argument("--keep-going", action="store_true",
                    help="do not end an episode when the task fails (to see the whole trajectory)")
    args = ap.parse_args(argv)
    if args.episodes < 1:
        raise UserError(f"--episodes must be >= 1, got {args.episodes}")
    output_dir(args.out, "--out", (FILE_NAME,))
    return args


def _main(argv: list[str]) -> None:
    args = parse_args(argv)
    torch.set_num_threads(1)
    try:
        env, actor = load(args, args.episodes, **({"fail_terminates": False} if args.keep_going else {}))
    except (ValueError, OSError) as exc:  # RunError, DatasetError, a bad controller or config
        raise UserError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from None
    try:
        out = args.out / FILE_NAME
        stats = record_trueadapt(env, actor, args.episodes, out)
    finally:
        env.close()
    print(json.dumps(stats))
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB); view with: pathrl-view {args.out}")


def main(argv: list[str] | None = None) -> int:
    """Entry point (argv: sys.argv[1:]); 0, or 2 with a one-line error on stderr."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
