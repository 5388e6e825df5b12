"""The plan of `make reproduce-tables`: every step (dataset, training, evaluation, baseline, measurement) of the
selected rows, in phases, each evaluation and baseline once even when several table rows use it.

Phases run in order (:data:`PHASES`); the steps of a phase in :data:`CONCURRENT` run ``--jobs`` at a time
(independent evaluations, one process each), the others one at a time: trainings (never two on 2 cores) and the
real-time measurements (they time computation, so they run on an otherwise idle machine).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from pathrl.repro import steps
from pathrl.repro import trueadapt as adapt
from pathrl.repro.layout import ROOT, Layout, Profile
from pathrl.repro.tables import PATH_CHANGE, REALTIME, ROWS, SWEEPS, baselines, evaluations, select

__all__ = ["CONCURRENT", "PHASES", "Plan", "Step", "build_plan", "check_only"]

PHASES = ("prepare", "evaluate", "timing")
CONCURRENT = {"evaluate"}


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
    # The simulated (PyBullet) evaluations, the longest steps, first: the concurrent phase then ends with
    # short steps on every lane.
    for e in sorted(evals, key=lambda e: not e.task):
        plan.add("evaluate", f"evaluate {e.id}", lambda e=e: steps.evaluate(e, profile, lay, reuse, logs))
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


def _trueadapt_steps(plan: Plan, profile: Profile, lay: Layout, only: set[str] | None, reuse: bool) -> None:
    """The TrueAdapt paper's Table I (the ball in PyBullet), then its limit validation and time per decision: the
    TrueAdapt family's registry steps (evaluate through ``pathrl-eval``, validate, timing)."""
    logs, raw = lay.out / "logs", lay.out / "raw"
    for a in adapt.evaluations(only):
        plan.add("evaluate", f"evaluate {a.id}", lambda a=a: steps.adapt_evaluate(a, profile, lay, reuse, logs))
    if only is None or adapt.VALIDATION_ID in only:
        n = 1000 if profile.name == "quick" else 100_000
        plan.add("evaluate", "TrueAdapt limit validation", lambda: steps.adapt_step(
            adapt.validation_command(ROOT, raw, n, reuse), logs / f"{adapt.VALIDATION_ID}.log"))
        timing = adapt.realtime_command  # the timed model of this layout, on its test split
        plan.add("timing", "TrueAdapt time per decision", lambda: steps.adapt_step(
            timing(ROOT, raw, lay.models, lay.test_data, 2000, reuse), logs / f"{adapt.REALTIME_ID}.log"))
