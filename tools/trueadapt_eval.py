"""Evaluate TrueAdapt: the reference without adaptation, or a trained run (Table I metrics), analytic or PyBullet ball.

    .venv/bin/python tools/trueadapt_eval.py --task on_plate --episodes 1000            # reference, no adaptation
    .venv/bin/python tools/trueadapt_eval.py --run runs/iiwa7_trueadapt_on_plate/seed0 [--open-loop]
    .venv/bin/python tools/trueadapt_eval.py --task in_place --backend pybullet         # the ball in PyBullet
    .venv/bin/python tools/trueadapt_eval.py --controller '{name: trueadapt_tray, kp: 2.25}'  # a controller
    .venv/bin/python tools/trueadapt_eval.py --run models/iiwa7_trueadapt_on_plate_tray  # config.yaml: controller:
    .venv/bin/python tools/trueadapt_eval.py --run runs/<run> --checkpoint runs/<run>/model_100.pt
    .venv/bin/python tools/trueadapt_eval.py --task on_plate --out results/raw/<name>   # also <name>/metrics.json

Trajectories 0 .. episodes-1 of the split (cycled), ``--num-envs`` at a time, deterministic policy actions. Prints
the success rate, the trajectory fraction executed before the task failed, the mean normalised |a| and |jerk|, the
mean ball offset from its start (m) and the limit violations of the commanded 240 Hz setpoints as JSON. Without
``--dataset``, a config's ``data/<robot>/<set>`` that is not on this machine falls back to the committed test split
``datasets/<robot>/<set>`` (``--split test`` only).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from pathrl.cli.common import ArgParser, UserError, compose, output_dir, run_cli, to_container
from pathrl.families.trueadapt import Source, controller_spec, evaluate_loaded
from pathrl.families.trueadapt import load as load_family
from pathrl.schema import TrainAppCfg

__all__ = ["controller_spec", "load", "main", "parse_args"]


def load(args: argparse.Namespace, num_envs: int, **overrides):
    """(env, actor) of the command line (``run``, ``task``, ``checkpoint``, ``controller``, ``backend``, ``split``,
    ``dataset``, ``seed``): the run's config (or the ``task`` experiment's) loaded by the TrueAdapt family
    (:func:`pathrl.families.trueadapt.load`); None for the reference without adaptation. ValueError / OSError on bad
    input."""
    ckpt = None
    if args.run is None:
        cfg = to_container(compose("train", [f"+experiment=iiwa7_trueadapt_{args.task}"], TrainAppCfg))
    else:
        from pathrl.runs import load_run

        cfg, ckpt, _ = load_run(args.run)
    spec = controller_spec(args.controller) if args.controller is not None else None
    src = Source(args.checkpoint, spec, args.backend, getattr(args, "workers", None), args.dataset, args.split,
                 args.seed)
    env, actor, args.resolved_dataset = load_family(cfg, ckpt, src, num_envs, **overrides)  # dataset: recorded
    return env, actor


def parse_args(argv: list[str]) -> argparse.Namespace:
    """The command line, checked (UserError: one line): counts >= 1, ``--out`` writable, before any work."""
    ap = ArgParser(prog="trueadapt_eval.py", description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", choices=["on_plate", "in_place"], default="on_plate", help="without --run")
    ap.add_argument("--run", type=Path, default=None, help="a run directory: evaluate its latest checkpoint")
    ap.add_argument("--dataset", default=None, help="dataset directory (default: the config's)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--num-envs", type=int, default=250)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--open-loop", action="store_true", help="the ball measurement stays at its initial value")
    ap.add_argument("--backend", choices=["analytic", "pybullet"], default="analytic", help="ball simulation")
    ap.add_argument("--controller", default=None, help="a controller spec (YAML mapping, e.g. "
                    "'{name: trueadapt_tray}') to evaluate on the --task experiment's config")
    ap.add_argument("--checkpoint", type=Path, default=None, help="with --run: this checkpoint, not the latest")
    ap.add_argument("--workers", type=int, default=None, help="PyBullet worker processes (default: the config's)")
    ap.add_argument("--out", type=Path, default=None, help="also write the result to OUT/metrics.json")
    args = ap.parse_args(argv)
    for flag, value in (("--episodes", args.episodes), ("--num-envs", args.num_envs), ("--workers", args.workers)):
        if value is not None and value < 1:
            raise UserError(f"{flag} must be >= 1, got {value}")
    if args.out is not None:
        output_dir(args.out, "--out", ("metrics.json",))
    return args


def _main(argv: list[str]) -> None:
    args = parse_args(argv)
    torch.set_num_threads(1)
    try:
        env, actor = load(args, min(args.num_envs, args.episodes), **({"obs_ball": False} if args.open_loop else {}))
    except (ValueError, OSError) as exc:  # RunError, DatasetError, a bad controller or config
        raise UserError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from None
    try:
        got = evaluate_loaded(env, actor, args.episodes)
    finally:
        env.close()
    keys = ("limit_violations", "limit_violations_by_kind", "setpoints_checked")
    res = {k: v for k, v in got.items() if k not in (*keys, "trajectories_in_split", "seconds")}
    res |= {"backend": args.backend, **{k: got[k] for k in keys}, "dataset": args.resolved_dataset,
            "split": args.split, "trajectories_in_split": got["trajectories_in_split"], "seconds": got["seconds"],
            "command": " ".join(["tools/trueadapt_eval.py", *argv])}
    print(json.dumps(res, indent=1))
    if args.out is not None:
        from pathrl.storage import write_json_atomic

        args.out.mkdir(parents=True, exist_ok=True)
        write_json_atomic(args.out / "metrics.json", res)


def main(argv: list[str] | None = None) -> int:
    """Entry point (argv: sys.argv[1:]); 0, or 2 with a one-line error on stderr."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
