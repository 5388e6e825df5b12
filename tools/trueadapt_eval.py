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
import time
from pathlib import Path

import torch

from pathrl.cli.common import ArgParser, UserError, compose, output_dir, run_cli, to_container
from pathrl.envs.device import EVAL_DEVICE
from pathrl.envs.trueadapt import build_trueadapt_env
from pathrl.eval.trueadapt import ObservingPolicy, evaluate, reference_policy, summary
from pathrl.eval.trueadapt_limits import LimitCounter
from pathrl.runs import committed_split
from pathrl.schema import TrainAppCfg


def controller_spec(text: str) -> dict:
    """``reference`` -> {"name": "reference"}; a YAML mapping ``{name: ..., <keys>}`` as it is."""
    import yaml

    spec = yaml.safe_load(text)
    spec = {"name": spec} if isinstance(spec, str) else spec
    if not isinstance(spec, dict):
        raise ValueError(f"--controller: expected a name or a YAML mapping, got {text!r}")
    return spec


def load(args: argparse.Namespace, num_envs: int, **overrides):
    """(env, actor) of the command line (``run``, ``task``, ``checkpoint``, ``controller``, ``backend``, ``split``,
    ``dataset``, ``seed``): the run's config (or the ``task`` experiment's) on `num_envs` envs without autoreset,
    `overrides` replacing env settings; the actor (obs -> actions) is ``--controller``, the run's controller or the
    run's checkpoint, None for the reference without adaptation. ValueError / OSError on bad input."""
    ckpt = None
    if args.run is None:
        cfg = to_container(compose("train", [f"+experiment=iiwa7_trueadapt_{args.task}"], TrainAppCfg))
    else:
        from pathrl.runs import load_run

        cfg, ckpt, _ = load_run(args.run)
        ckpt = args.checkpoint or ckpt
    spec = controller_spec(args.controller) if args.controller is not None else cfg.get("controller")
    cfg["task"]["backend"] = args.backend
    if getattr(args, "workers", None) is not None:
        cfg["task"]["workers"] = args.workers
    dataset = args.dataset or committed_split(cfg["dataset"]["path"], args.split)
    args.resolved_dataset = dataset  # recorded with the result
    # the evaluation device, not the one the run was trained on (a GPU-trained run evaluates on a CPU-only machine)
    env = build_trueadapt_env(cfg, args.split, num_envs, dataset, args.seed, autoreset=False,
                              **{"device": EVAL_DEVICE, **overrides})
    try:
        if spec is not None:
            from pathrl.runs import make_controller

            return env, make_controller(spec, env)
        if args.run is not None:
            from pathrl.runs import load_policy

            return env, load_policy(cfg, env, ckpt)
        return env, None
    except BaseException:
        env.close()
        raise


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
    policy = reference_policy if actor is None else ObservingPolicy(actor)
    traj = torch.arange(args.episodes) % env.bank.num
    limits = LimitCounter(env)
    t0 = time.perf_counter()
    try:
        res = summary(evaluate(env, policy, traj, limits)) | {"backend": args.backend}
    finally:
        env.close()
    res |= {"limit_violations": limits.counts["total"], "limit_violations_by_kind": limits.counts,
            "setpoints_checked": limits.checked, "dataset": args.resolved_dataset, "split": args.split,
            "trajectories_in_split": env.bank.num,
            "seconds": round(time.perf_counter() - t0, 1), "command": " ".join(["tools/trueadapt_eval.py", *argv])}
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
