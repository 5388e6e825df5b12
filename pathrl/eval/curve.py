"""Time to quality: the checkpoints of a training run evaluated on a test split, against wall time and env steps.

Every checkpoint records the training wall time at which it was written (``infos.wall_time_s``, see
:class:`pathrl.train.runner.PathRLRunner`), so a curve needs no log: evaluate each checkpoint with the
paper's protocol (:func:`pathrl.eval.evaluate.evaluate`, deterministic policy, 1200 test segments) and read
off the first checkpoint that meets a target (duration and mean Cartesian deviation, no limit violation).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from pathrl.config.paper import load as load_paper
from pathrl.storage import atomic_write, checkpoint_iteration, load_checkpoint, run_checkpoints

__all__ = ["CurvePoint", "CurveProtocol", "PAPER_EPISODES", "Target", "checkpoint_wall_time", "checkpoints",
           "curve_point", "curve_record", "evaluate_curve", "first_reaching", "plot_curves"]

#: Test segments per evaluation with ``segments=paper``: the paper's protocol.
PAPER_EPISODES = int(load_paper("tracking").value("episodes"))


@dataclass(frozen=True)
class CurvePoint:
    """One evaluated checkpoint."""

    iteration: int  # PPO iterations done (the checkpoint of iteration k, 0-based, has k + 1)
    env_steps: int
    wall_time_s: float | None  # training wall time when the checkpoint was written; None for older runs
    duration_s: float  # mean episode duration (s)
    cart_pos_dev_mean_cm: float
    limit_violations: int
    end_of_path_s: float | None = None  # mean time to the path end over the episodes that got there (s)
    task_failed_pct: float | None = None  # feedback tasks: share of episodes whose task failed (ball lost, fall)


@dataclass(frozen=True)
class Target:
    """A quality to reach: duration <= max_duration_s at mean Cartesian deviation <= max_dev_cm, no violation."""

    max_duration_s: float
    max_dev_cm: float

    def met(self, p: CurvePoint) -> bool:
        """True if the point `p` reaches the target."""
        return p.duration_s <= self.max_duration_s and p.cart_pos_dev_mean_cm <= self.max_dev_cm \
            and p.limit_violations == 0


def checkpoints(run_dir: Path, every: int) -> list[tuple[int, Path]]:
    """(iteration index, path) of the run's ``model_<k>.pt`` with k a multiple of `every`, plus the last one."""
    if every < 1:
        raise ValueError(f"every: expected a positive number of iterations, got {every}")
    found = [(checkpoint_iteration(p), p) for p in run_checkpoints(run_dir)]
    if not found:
        raise ValueError(f"{run_dir}: no checkpoints (model_<iteration>.pt)")
    return [(k, p) for i, (k, p) in enumerate(found) if k % every == 0 or i == len(found) - 1]


def checkpoint_wall_time(path: Path) -> float | None:
    """The training wall time (s) stored in a checkpoint, None if it predates the record."""
    infos = load_checkpoint(path).get("infos") or {}
    t = infos.get("wall_time_s")
    return None if t is None else float(t)


@dataclass(frozen=True)
class CurveProtocol:
    """How each checkpoint of a curve is evaluated: `episodes` (None: one per path with ``full``), `segments` (the
    paper's random segments or ``full`` paths), `backend` (the simulator of a feedback task, ``pybullet`` or
    ``analytic``) and `out_of_limits` (``refuse`` or ``clip`` paths that leave the position limits), as in
    :class:`pathrl.eval.evaluate.EvalOptions`."""

    episodes: int | None = PAPER_EPISODES
    segments: str = "paper"
    backend: str = "pybullet"
    out_of_limits: str = "refuse"


def evaluate_curve(run_dir: Path, dataset: str, out_dir: Path, every: int = 50,
                   protocol: CurveProtocol = CurveProtocol(), progress: bool = True) -> list[CurvePoint]:
    """Evaluate every selected checkpoint of `run_dir` on the test split of `dataset` as `protocol` says.

    Each evaluation's metrics.json lands in ``out_dir/model_<k>/``; an existing one for the same dataset,
    segments, episode count and feedback simulator is reused, so an interrupted curve continues where it stopped.
    """
    from pathrl.eval.evaluate import EvalOptions, evaluate

    steps_per_it = _steps_per_iteration(run_dir)
    points = []
    for k, ckpt in checkpoints(run_dir, every):
        out = Path(out_dir) / ckpt.stem
        m = _cached(out / "metrics.json", dataset, protocol)
        if m is None:
            if progress:
                print(f"evaluate {ckpt}")
            m = evaluate(run_dir, EvalOptions(dataset_path=dataset, episodes=protocol.episodes,
                                              segments=protocol.segments, out_dir=out, record=False, progress=False,
                                              checkpoint=ckpt.name, backend=protocol.backend,
                                              out_of_limits=protocol.out_of_limits))
        points.append(curve_point(k + 1, steps_per_it, checkpoint_wall_time(ckpt), m))
    return points


def curve_point(iteration: int, steps_per_iteration: int, wall_time_s: float | None, metrics: dict) -> CurvePoint:
    """The curve point of one checkpoint from its evaluation's `metrics` (``metrics.json``)."""
    end, failed = metrics.get("duration_end_of_path_s"), metrics.get("task_failed_pct")
    return CurvePoint(iteration, iteration * steps_per_iteration, wall_time_s, float(metrics["duration_s"]),
                      float(metrics["cart_pos_dev_mean_cm"]), int(metrics["limit_violations"]),
                      None if end is None else float(end), None if failed is None else float(failed))


def first_reaching(points: list[CurvePoint], target: Target) -> CurvePoint | None:
    """The earliest point that meets `target` (None if none does)."""
    return next((p for p in sorted(points, key=lambda p: p.iteration) if target.met(p)), None)


def curve_record(points: list[CurvePoint], target: Target | None, meta: dict) -> dict:
    """JSON-ready record of a curve: the points, the target and when it was first met."""
    hit = first_reaching(points, target) if target else None
    return {**meta, "target": asdict(target) if target else None, "points": [asdict(p) for p in points],
            "reached": asdict(hit) if hit else None,
            "minutes_to_target": None if hit is None or hit.wall_time_s is None else hit.wall_time_s / 60.0}


def plot_curves(curves: dict[str, list[CurvePoint]], target: Target | None, path: Path, title: str = "") -> None:
    """Duration and mean Cartesian deviation (log scale) against training wall time (top) and env steps
    (bottom), one line per run; the target as dashed lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    for (label, pts), marker in zip(curves.items(), "osd^v<>", strict=False):
        xs = ([(p.wall_time_s or float("nan")) / 60.0 for p in pts], [p.env_steps / 1e6 for p in pts])
        for row, x in zip(axes, xs, strict=True):
            row[0].plot(x, [p.duration_s for p in pts], marker=marker, ms=3, label=label)
            row[1].plot(x, [p.cart_pos_dev_mean_cm for p in pts], marker=marker, ms=3, label=label)
    for row, xlabel in zip(axes, ("training wall time (min)", "env steps (M)"), strict=True):
        for ax, name, lim in ((row[0], "duration (s)", target and target.max_duration_s),
                              (row[1], "mean Cartesian deviation (cm)", target and target.max_dev_cm)):
            if lim:
                ax.axhline(lim, color="k", ls="--", lw=0.8, label="target")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(name)
            ax.grid(alpha=0.3)
        row[1].set_yscale("log")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110))
    plt.close(fig)


def _steps_per_iteration(run_dir: Path) -> int:
    summary = Path(run_dir) / "summary.json"
    if summary.is_file():
        s = json.loads(summary.read_text())
        if s.get("steps_per_iteration"):
            return int(s["steps_per_iteration"])
    import yaml

    cfg = yaml.safe_load((Path(run_dir) / "config.yaml").read_text())
    return int(cfg["agent"]["num_steps_per_env"]) * int(cfg["env"]["num_envs"])


def _cached(path: Path, dataset: str, protocol: CurveProtocol) -> dict | None:
    if not path.is_file():
        return None
    m = json.loads(path.read_text())
    same = m.get("dataset") == str(dataset) and m.get("segments", "paper") == protocol.segments
    task = m.get("task")  # a feedback task's metrics name the simulator that produced them
    same = same and (task is None or task.get("simulator") == protocol.backend)
    return m if same and (protocol.episodes is None or m.get("episodes") == protocol.episodes) else None
