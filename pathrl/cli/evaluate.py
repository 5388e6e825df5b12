"""``pathrl-eval``: evaluate a training run or a shipped model directory.

    pathrl-eval run_dir=models/iiwa7_random [dataset=NAME | dataset.path=DIR] [split=test]
                [episodes=N] [segments=paper|full] [seed=0] [out=DIR]
                [task=ball_on_plate|standing] [backend=pybullet|analytic] [compile_limits=true|false]
                [open_loop=true|false] [checkpoint=model_K.pt] [dataset.out_of_limits=refuse|clip]

``task`` adds a feedback task to a run trained without one (its sensor values stay unobserved); runs with
a task are simulated with ``backend`` (default PyBullet). ``open_loop=true`` freezes the task's sensor at
its first value of each episode. ``checkpoint`` evaluates that checkpoint of a training run instead of
its latest. ``run_dir`` may also be a model-based controller's directory
(``models/iiwa7_ball_tray_controller``).
"""

from __future__ import annotations

from pathlib import Path

from pathrl.cli.common import UserError, parse_key_values, run_cli

__all__ = ["OFFSET_WARN_RAD", "main"]

USAGE = ("usage: pathrl-eval run_dir=RUN [dataset=NAME | dataset.path=DIR] [split=test] [episodes=N] "
         "[segments=paper|full] [seed=S] [out=DIR] [record=true|false] [task=ball_on_plate|standing] "
         "[backend=pybullet|analytic] [compile_limits=true|false] [open_loop=true|false] [checkpoint=model_K.pt] "
         "[dataset.out_of_limits=refuse|clip]")
KEYS = {"run_dir", "dataset", "dataset.path", "split", "episodes", "segments", "seed", "out", "record", "num_envs",
        "task", "backend", "compile_limits", "open_loop", "checkpoint", "dataset.out_of_limits"}


def _int(args: dict[str, str], key: str, default: int | None) -> int | None:
    if key not in args:
        return default
    try:
        return int(args[key])
    except ValueError:
        raise UserError(f"{key} must be an integer, got {args[key]!r}") from None


def _bool(args: dict[str, str], key: str, default: bool) -> bool:
    value = args.get(key, str(default)).lower()
    if value not in ("true", "false"):
        raise UserError(f"{key} must be true or false, got {args[key]!r}")
    return value == "true"


def _main(argv: list[str]) -> None:
    from pathrl.dataset.io import DatasetError
    from pathrl.envs.registry import TASKS
    from pathrl.eval.evaluate import RunError, evaluate, load_run

    args = parse_key_values(argv, KEYS, USAGE, required=("run_dir",))
    segments = args.get("segments", "paper")
    if segments not in ("paper", "full"):
        raise UserError(f"segments must be paper or full, got {segments!r}")
    path_tasks = [name for name, t in TASKS.items() if not t.adapt]  # tasks an evaluation can add to a run
    if args.get("task", "tracking") not in path_tasks:
        raise UserError(f"task must be one of {', '.join(path_tasks)}, got {args['task']!r}")
    if args.get("dataset.out_of_limits", "refuse") not in ("refuse", "clip"):
        raise UserError(f"dataset.out_of_limits must be refuse or clip, got {args['dataset.out_of_limits']!r}")
    if args.get("backend", "pybullet") not in ("pybullet", "analytic"):
        raise UserError(f"backend must be pybullet or analytic, got {args['backend']!r}")
    flags = {"record": _bool(args, "record", True), "compile_limits": _bool(args, "compile_limits", False),
             "open_loop": _bool(args, "open_loop", False)}
    episodes = _int(args, "episodes", None)
    if episodes is not None and episodes < 1:
        raise UserError(f"episodes must be >= 1, got {episodes}")
    num_envs = _int(args, "num_envs", 1200)
    if num_envs is None or num_envs < 1:
        raise UserError(f"num_envs must be >= 1, got {args.get('num_envs')}")
    run_dir = Path(args["run_dir"])
    dataset_path = args.get("dataset.path")
    if "dataset" in args:
        try:
            cfg, _, _ = load_run(run_dir)
        except RunError as exc:
            raise UserError(str(exc)) from None
        dataset_path = str(Path("data") / cfg["robot"]["name"] / args["dataset"])
    try:
        m = evaluate(run_dir, dataset_path, args.get("split", "test"), episodes, segments,
                     _int(args, "seed", 0) or 0, Path(args["out"]) if "out" in args else None,
                     num_envs=num_envs,
                     record=flags["record"], task=args.get("task"), backend=args.get("backend", "pybullet"),
                     compile_limits=flags["compile_limits"], open_loop=flags["open_loop"],
                     checkpoint=args.get("checkpoint"), out_of_limits=args.get("dataset.out_of_limits", "refuse"))
    except (RunError, DatasetError) as exc:
        raise UserError(str(exc)) from None
    _print_table(m)


def _print_table(m: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"{m['robot']} on {m['dataset']} ({m['split']}, {m['segments']}, {m['episodes']} episodes)")
    t.add_column("metric")
    t.add_column("value", justify="right")
    for k in ("duration_s", "joint_dev_mean_rad", "joint_dev_max_rad", "joint_dev_final_rad",
              "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm", "cart_pos_dev_final_cm",
              "cart_rot_dev_mean_deg", "cart_rot_dev_max_deg", "cart_rot_dev_final_deg",
              "duration_end_of_path_s", "terminated_early_pct", "task_failed_pct", "limit_violations"):
        if k not in m:
            continue
        v = m[k]
        t.add_row(k, f"{v:.3f}" if isinstance(v, float) else str(v))
    Console().print(t)
    if "per_joint" in m:
        print(_offset_line(m["per_joint"]))


#: A path joint whose mean signed error (commanded minus reference) exceeds this is listed under the table (rad).
OFFSET_WARN_RAD = 0.02


def _offset_line(per_joint: dict[str, dict[str, float]]) -> str:
    """One line naming the joints held off the path by more than :data:`OFFSET_WARN_RAD` on average (or none)."""
    from pathrl.eval.metrics import offset_joints

    big = offset_joints(per_joint, OFFSET_WARN_RAD)
    listed = ", ".join(f"{n} {per_joint[n]['offset_rad']:+.3f} ({100 * per_joint[n]['share']:.0f} %)" for n in big)
    return f"joint offsets > {OFFSET_WARN_RAD} rad (mean signed error, share of squared deviation): {listed or 'none'}"


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pathrl-eval key=value ...`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
