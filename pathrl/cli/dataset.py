"""``pathrl-dataset``: generate, import and inspect reference-path datasets.

    pathrl-dataset generate robot=iiwa7 dataset=random [dataset.num_train=N dataset.num_test=N
                            dataset.seed=S dataset.path=DIR workers=2 overwrite=true]
    pathrl-dataset import --format kiemel-json --robot ROBOT [--overwrite] SRC_DIR DEST
    pathrl-dataset import --format csv|npy --robot ROBOT [--degrees] [--split test] [--overwrite] SRC DEST
    pathrl-dataset info DEST

Bad input -> one line on stderr, exit code 2, nothing written.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from pathrl.cli.common import UserError, compose, output_dir, run_cli, to_container

__all__ = ["cmd_generate", "cmd_import", "cmd_info", "main", "print_info", "print_limits"]

USAGE = __doc__.split("\n\n")[1]


class _Parser(argparse.ArgumentParser):
    """argparse parser whose errors raise UserError (one line, exit code 2) instead of exiting."""
    def error(self, message: str) -> None:  # one line, exit code 2 via UserError
        """Raise UserError with the parser's message instead of printing usage and exiting."""
        raise UserError(f"{self.prog}: {message}")


def _fmt_stats(st: Mapping[str, Any]) -> str:
    """One line of a split's statistics: path count, knots min/mean/max, length min/mean/max (rad), max knot gap."""
    if not st or not st.get("count"):
        return "0 paths"
    k, length = st["knots"], st["length"]
    return (
        f"{st['count']} paths, knots {k['min']}/{k['mean']:.1f}/{k['max']}, "
        f"length {length['min']:.2f}/{length['mean']:.2f}/{length['max']:.2f} rad, "
        f"max knot gap {st['max_knot_gap']:.4f}"
    )


def print_info(meta: Mapping[str, Any], path: str, out=None) -> None:
    """Print a dataset's ``dataset.json`` metadata `meta` (found at `path`) to `out` (default stdout): format,
    robot, hash, splits, knot strategies and per-split statistics (path lengths in rad)."""
    out = out or sys.stdout
    print(f"dataset   {path}", file=out)
    print(
        f"format    {meta.get('format')}  source {meta.get('source')}  created {meta.get('created')}",
        file=out,
    )
    print(
        f"robot     {meta.get('robot')}  kind {meta.get('kind')}  seed {meta.get('seed')}  "
        f"path joints {len(meta.get('path_joints', []))}",
        file=out,
    )
    print(f"hash      {meta.get('content_hash')}", file=out)
    print("splits    " + ", ".join(f"{s} {n}" for s, n in meta.get("splits", {}).items()), file=out)
    if meta.get("default_knots"):
        print(f"knots     default strategy {json.dumps(meta['default_knots'])}", file=out)
    if meta.get("reference_max_knot_gap") is not None:
        print(f"reference max knot gap (spline_config) {meta['reference_max_knot_gap']}", file=out)
    print("stats     (knots min/mean/max, length min/mean/max)", file=out)
    for split, by_strategy in meta.get("stats", {}).items():
        for strategy, st in by_strategy.items():
            print(f"  {split:5s} {strategy:22s} {_fmt_stats(st)}", file=out)
    if meta.get("kind") == "trueadapt" and meta.get("trajectories"):  # time-parameterised trajectories
        from pathrl.dataset.trueadapt import format_trajectory_stats

        print(f"samples   every {meta.get('sample_dt')} s (the knots of a path are its samples in time)", file=out)
        for line in format_trajectory_stats(meta["trajectories"]):
            print(line, file=out)
    gen = meta.get("generator") or {}
    if gen:
        shown = {k: v for k, v in gen.items() if k != "robot_config"}
        print(f"generator {json.dumps(shown, sort_keys=True)}", file=out)
    if meta.get("generation"):
        print(f"generation {json.dumps(meta['generation'])}", file=out)


def print_limits(ds, out=None) -> None:
    """Per split: do the paths stay inside the position limits of the dataset's robot (if pathrl knows it)?"""
    from pathrl.dataset.limits import LIMIT_TOL, limit_excess
    from pathrl.robot.external import load_robot_by_name
    from pathrl.robot.model import RobotConfigError

    try:
        robot = load_robot_by_name(str(ds.meta.get("robot")))
    except (RobotConfigError, ValueError, KeyError):
        print(f"limits    robot {ds.meta.get('robot')!r} unknown to pathrl: not checked", file=out or sys.stdout)
        return
    if list(robot.path_joints) != list(ds.meta.get("path_joints", robot.path_joints)):
        print(f"limits    path joints differ from robot {robot.name!r}: not checked", file=out or sys.stdout)
        return
    for split, sp in ds.splits.items():
        ex = limit_excess(sp.knots, robot)
        state = ("inside" if not ex["paths_outside"] else
                 f"{ex['paths_outside']} of {ex['paths']} paths OUTSIDE, up to {1e3 * ex['max_excess_rad']:.3g} mrad "
                 f"({ex['joint']}); load with dataset.out_of_limits=clip")
        print(f"limits    {split:5s} position limits of {robot.name} (tolerance {LIMIT_TOL:g} rad): {state}",
              file=out or sys.stdout)


def cmd_generate(overrides: Sequence[str]) -> None:
    """``pathrl-dataset generate key=value ...``: compose ``conf/dataset_app.yaml`` with the overrides, generate the
    dataset and print its summary; bad overrides or generation errors are one-line :class:`UserError`."""
    from pathrl.datagen.generate import generate_dataset
    from pathrl.datagen.generators.context import GenerationError
    from pathrl.dataset.io import DatasetError
    from pathrl.robot.model import RobotConfigError

    bad = [o for o in overrides if "=" not in o]
    if bad:
        raise UserError(f"generate: expected key=value overrides, got {bad[0]!r}")
    from pathrl.schema import DatasetAppCfg

    cfg = compose("dataset_app", overrides, DatasetAppCfg)
    output_dir(str(cfg.dataset.path), "dataset.path")
    t0 = time.perf_counter()
    try:
        ds = generate_dataset(
            to_container(cfg.robot),
            to_container(cfg.dataset),
            workers=int(cfg.workers),
            overwrite=bool(cfg.overwrite),
            progress=sys.stderr.isatty(),
        )
    except (DatasetError, RobotConfigError, GenerationError) as exc:
        raise UserError(str(exc)) from None
    print(f"wrote {ds.path} in {time.perf_counter() - t0:.1f} s")
    print_info(ds.meta, str(ds.path))


def cmd_import(argv: Sequence[str]) -> None:
    """``pathrl-dataset import --format FMT --robot R SRC DEST``: convert paths into a dataset at DEST: the paper's
    original format (``kiemel-json``, :mod:`pathrl.dataset.kiemel`) or joint waypoints (``csv``, ``npy``: one file per
    path, SRC a file or a directory; :mod:`pathrl.dataset.waypoints`); print its summary and limit check."""
    from pathrl.dataset.io import DatasetError
    from pathrl.dataset.kiemel import import_kiemel
    from pathrl.dataset.waypoints import FORMATS, import_waypoints
    from pathrl.robot.external import load_robot_by_name
    from pathrl.robot.model import RobotConfigError

    ap = _Parser(prog="pathrl-dataset import", add_help=True)
    ap.add_argument("--format", required=True, choices=["kiemel-json", *FORMATS])
    ap.add_argument("--robot", required=True, help="conf/robot name, e.g. iiwa7")
    ap.add_argument("--overwrite", action="store_true")
    ap.add_argument("--kind", default=None, help="dataset kind to record (default: source dir name)")
    ap.add_argument("--degrees", action="store_true", help="csv/npy: the waypoints are in degrees (default radians)")
    ap.add_argument("--split", default="test", help="csv/npy: the split the paths go to (default test)")
    ap.add_argument("--reflections", action="store_true",
                    help="kiemel-json: store every path once per reflection vector of its spline_config.json")
    ap.add_argument("src_dir", help="kiemel-json: a directory; csv/npy: one path file or a directory of them")
    ap.add_argument("dest")
    args = ap.parse_args(list(argv))
    if args.format == "kiemel-json" and (args.degrees or args.split != "test"):
        raise UserError("pathrl-dataset import: --degrees and --split are for --format csv and npy")
    if args.format != "kiemel-json" and args.reflections:
        raise UserError("pathrl-dataset import: --reflections is for --format kiemel-json")
    if Path(args.dest).exists() and not args.overwrite:
        raise UserError(f"{args.dest}: already exists (pass --overwrite to replace it)")
    output_dir(args.dest, "DEST")
    t0 = time.perf_counter()
    try:
        robot = load_robot_by_name(args.robot)
        if args.format == "kiemel-json":
            ds = import_kiemel(args.src_dir, args.dest, robot, overwrite=args.overwrite, kind=args.kind,
                               reflections=args.reflections)
        else:
            ds = import_waypoints(args.src_dir, args.dest, robot, args.format, args.degrees, args.split,
                                  args.overwrite, args.kind)
    except (DatasetError, RobotConfigError) as exc:
        raise UserError(str(exc)) from None
    print(f"imported {args.src_dir} -> {ds.path} in {time.perf_counter() - t0:.1f} s")
    print_info(ds.meta, str(ds.path))
    print_limits(ds)


def cmd_info(argv: Sequence[str]) -> None:
    """``pathrl-dataset info DEST``: print a dataset's summary and its position-limit check."""
    from pathrl.dataset.io import DatasetError, load_dataset

    ap = _Parser(prog="pathrl-dataset info")
    ap.add_argument("dest")
    args = ap.parse_args(list(argv))
    try:
        ds = load_dataset(args.dest)
    except DatasetError as exc:
        raise UserError(str(exc)) from None
    print_info(ds.meta, str(ds.path))
    print_limits(ds)


def _main(argv: list[str]) -> None:
    """Dispatch `argv` (command first) to the generate / import / info command; UserError for a missing or unknown
    one."""
    if not argv or argv[0] in ("-h", "--help"):
        if argv:
            print(USAGE)
            return
        raise UserError("missing command; usage: pathrl-dataset {generate,import,info} ...")
    cmd, rest = argv[0], argv[1:]
    if cmd == "generate":
        cmd_generate(rest)
    elif cmd == "import":
        cmd_import(rest)
    elif cmd == "info":
        cmd_info(rest)
    else:
        raise UserError(f"unknown command {cmd!r}; choose one of generate, import, info")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pathrl-dataset {generate,import,info}`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
