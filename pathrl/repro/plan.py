"""The plan of `make reproduce-tables`: every step (dataset, training, evaluation, baseline, measurement) of the
selected rows, in phases, each evaluation and baseline once even when several table rows use it.

Phases run in order (:data:`PHASES`); the steps of a phase in :data:`CONCURRENT` run ``--jobs`` at a time
(independent evaluations: one process per evaluation, or per batch of them sharing its imports and PyBullet scenes;
baselines), the others one at a time: trainings (never two on 2 cores) and the
real-time measurements (they time computation, so they run on an otherwise idle machine).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pathrl.repro import steps
from pathrl.repro import trueadapt as adapt
from pathrl.repro.layout import ROOT, Layout, Profile
from pathrl.repro.tables import PATH_CHANGE, REALTIME, ROWS, SWEEPS, baselines, evaluations, select

__all__ = ["BATCH", "CONCURRENT", "PHASES", "Plan", "Step", "build_plan", "check_only"]

PHASES = ("prepare", "evaluate", "timing")
CONCURRENT = {"evaluate"}

#: Evaluations per ``pathrl-eval batch=FILE`` process (:func:`pathrl.repro.steps.evaluate_batch`): enough to share
#: the imports and the PyBullet ball scenes, few enough that the ``--jobs`` lanes stay balanced.
BATCH = 9


@dataclass
class Step:
    """One step: its label on the console, what it runs, its phase; after running, why it failed and its time."""

    label: str
    run: Callable[[], None]
    phase: str
    failed: str | None = None
    seconds: float = 0.0


@dataclass
class Plan:
    """The steps of a reproduction, in the order they are added (within a phase: the order they start)."""

    steps: list[Step] = field(default_factory=list)

    def add(self, phase: str, label: str, fn: Callable[[], None]) -> None:
        """Add step `label` running `fn` to `phase` (one of :data:`PHASES`)."""
        if phase not in PHASES:
            raise ValueError(f"unknown phase {phase!r}; known: {', '.join(PHASES)}")
        self.steps.append(Step(label, fn, phase))

    def phase(self, name: str) -> list[Step]:
        """The steps of phase `name`, in order."""
        return [s for s in self.steps if s.phase == name]


def check_only(only: set[str]) -> None:
    """ValueError (one line) naming the names of `only` that are neither a row's model, a TrueAdapt evaluation or
    a sweeps/ table."""
    known = {r.evaluation.model for r in ROWS} | adapt.names() | set(SWEEPS)
    unknown = only - known
    if unknown:
        raise ValueError(f"--only: unknown model or table(s) {sorted(unknown)}; known: {sorted(known)}")


def build_plan(profile: Profile, lay: Layout, only: set[str] | None, train: bool = False, reuse: bool = False,
               jobs: int = 1) -> Plan:
    """The steps that fill the rows of `only` (None: every row, with the measurements and motion-profile tables):
    with `train` their datasets and trainings first; `reuse` keeps results already in ``lay.out``."""
    evals, logs = evaluations(select(only)), lay.out / "logs"
    plan = Plan()
    if train:
        _training_steps(plan, profile, lay, evals, reuse)
    # The longest steps first (the TrueAdapt batches, the standing robots in PyBullet): the concurrent phase then
    # ends with short steps on every lane.
    _trueadapt_evaluations(plan, profile, lay, only, reuse)
    for e in (e for e in evals if e.task == "standing"):  # a standing scene is never kept: one process each
        plan.add("evaluate", f"evaluate {e.id}", lambda e=e: steps.evaluate(e, profile, lay, reuse, logs))
    for name, task in (("ball", "ball_on_plate"), ("tracking", None)):
        _batches(plan, name, [e for e in evals if e.task == task],
                 lambda e: steps.eval_job(e, profile, lay, reuse), logs)
    toppra_workers = 1 if jobs > 1 else 2
    for b in baselines(select(only)):
        plan.add("evaluate", f"TOPP-RA {b.robot}/{b.dataset} ({b.segments})",
                 lambda b=b: steps.toppra(b, profile, lay, reuse, logs, toppra_workers))
    _trueadapt_steps(plan, profile, lay, only, reuse)
    if only is None:
        for key, robot, split in REALTIME:
            plan.add("timing", f"real time {key}", lambda key=key, robot=robot, split=split: steps.realtime(
                key, robot, split, profile, lay, reuse, logs))
        plan.add("evaluate", "motion-profile tables (pathrl-industrial)", lambda: steps.industrial(lay, reuse, logs))
        for key, model, split in PATH_CHANGE:  # times re-plans: on the otherwise idle machine, like Table IX
            plan.add("timing", f"path changes {key}", lambda key=key, model=model, split=split: steps.path_change(
                key, model, split, profile, lay, reuse, logs))
    return plan


def _training_steps(plan: Plan, profile: Profile, lay: Layout, evals: list, reuse: bool) -> None:
    """--train: the quick profile's tiny datasets, then every policy's training (a warm start's sources first)."""
    logs = lay.out / "logs"
    if profile.name == "quick":
        for robot, name, test_dir in sorted({(e.data_robot, e.dataset, e.test_dir) for e in evals}):
            plan.add("prepare", f"dataset {robot}/{test_dir}", lambda robot=robot, name=name, test_dir=test_dir:
                     steps.tiny_dataset(robot, name, test_dir, profile, lay, reuse, logs))
    for model, e in steps.training_jobs(evals).items():
        plan.add("prepare", f"train {model}", lambda model=model, e=e: steps.train_and_ship(model, e, profile, lay,
                                                                                           logs))


def _batches(plan: Plan, name: str, items: list, job: Callable[[Any], steps.EvalJob | None], logs: Path) -> None:
    """One evaluate step per :data:`BATCH` consecutive `items` (each with an ``id``), labelled ``<name>_<k>``: their
    ``job(item)`` in one ``pathrl-eval batch=FILE`` process (:func:`pathrl.repro.steps.evaluate_batch`)."""
    for k in range(0, len(items), BATCH):
        chunk, label = items[k:k + BATCH], f"{name}_{k // BATCH + 1}"
        makers = [lambda item=item: job(item) for item in chunk]
        plan.add("evaluate", f"evaluate {len(chunk)} ({label}: {chunk[0].id} ...)",
                 lambda label=label, makers=makers: steps.evaluate_batch(label, makers, logs))


def _trueadapt_evaluations(plan: Plan, profile: Profile, lay: Layout, only: set[str] | None, reuse: bool) -> None:
    """The TrueAdapt paper's Table I (the ball in PyBullet): ``pathrl-eval`` batches of :data:`BATCH` evaluations."""
    _batches(plan, "trueadapt", adapt.evaluations(only), lambda a: steps.adapt_job(a, profile, lay, reuse),
             lay.out / "logs")


def _trueadapt_steps(plan: Plan, profile: Profile, lay: Layout, only: set[str] | None, reuse: bool) -> None:
    """The TrueAdapt table's limit validation and time per decision: the TrueAdapt family's registry steps
    (validate, timing; its evaluations: :func:`_trueadapt_evaluations`)."""
    logs, raw = lay.out / "logs", lay.out / "raw"
    if only is None or adapt.VALIDATION_ID in only:
        n = 1000 if profile.name == "quick" else 100_000
        plan.add("evaluate", "TrueAdapt limit validation", lambda: steps.adapt_step(
            adapt.validation_command(ROOT, raw, n, reuse), logs / f"{adapt.VALIDATION_ID}.log"))
        timing = adapt.realtime_command  # the timed model of this layout, on its test split
        plan.add("timing", "TrueAdapt time per decision", lambda: steps.adapt_step(
            timing(ROOT, raw, lay.models, lay.test_data, 2000, reuse), logs / f"{adapt.REALTIME_ID}.log"))
