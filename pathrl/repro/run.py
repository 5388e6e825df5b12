"""Running a reproduction: the plan's phases with a progress bar, then every table rendered
(:func:`reproduce`, what ``tools/reproduce_tables.py`` calls)."""

from __future__ import annotations

import time
from pathlib import Path

from pathrl.repro.layout import PROFILES, ROOT, Layout
from pathrl.repro.outputs import write_outputs
from pathrl.repro.plan import CONCURRENT, PHASES, Plan, Step, build_plan, check_only
from pathrl.repro.steps import StepFailed

__all__ = ["check", "default_out", "reproduce", "run_plan"]


def default_out(profile: str) -> Path:
    """The output directory of `profile` without ``--out``: results/ (full) or results/quick/."""
    return ROOT / ("results" if profile == "full" else "results/quick")


def _runner(bar, task, running: list[str], lock):
    """The function running one step with the progress bar's bookkeeping (a failed step is printed, not raised)."""

    def run(step: Step) -> None:
        with lock:
            running.append(step.label)
            bar.update(task, description=" | ".join(running))
        ts = time.perf_counter()
        try:
            step.run()
        except (StepFailed, FileNotFoundError) as exc:
            step.failed = str(exc)
            bar.console.print(f"[red]FAILED[/red] {step.label}: {exc}")
        step.seconds = time.perf_counter() - ts
        with lock:
            running.remove(step.label)
            bar.console.print(f"{'failed' if step.failed else 'done':>6}  {step.label}  ({step.seconds:.0f} s)")
            bar.update(task, advance=1, description=" | ".join(running))

    return run


def run_plan(plan: Plan, jobs: int) -> None:
    """Run the plan's phases in order with a progress bar; a failed step is reported and does not stop the
    others (its rows show a dash)."""
    from concurrent.futures import ThreadPoolExecutor
    from threading import Lock

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("[bold]reproduce-tables"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.description}")) as bar:
        run = _runner(bar, bar.add_task("", total=len(plan.steps)), [], Lock())
        for phase in PHASES:
            steps = plan.phase(phase)
            if phase in CONCURRENT and jobs > 1:
                with ThreadPoolExecutor(jobs) as pool:
                    list(pool.map(run, steps))
            else:
                for step in steps:
                    run(step)


def check(profile: str, only: str, jobs: int) -> None:
    """ValueError (one line) on an unknown `profile`, a name of `only` (comma-separated) that is no row, TrueAdapt
    evaluation or sweeps/ table, or `jobs` < 1."""
    if profile not in PROFILES:
        raise ValueError(f"--profile must be one of {', '.join(sorted(PROFILES))}, got {profile!r}")
    if jobs < 1:
        raise ValueError(f"--jobs must be >= 1, got {jobs}")
    check_only(set(filter(None, only.split(","))))


def reproduce(profile: str = "full", only: str = "", train: bool = False, reuse: bool = False, out: Path | None = None,
              jobs: int = 1) -> int:
    """Run the plan of `only` (comma-separated model or sweeps/ table names; empty: everything) and render every
    table into `out` (default :func:`default_out`); prints the tables and a summary, returns the exit code (1 when
    a step failed). ValueError (one line, :func:`check`) on bad arguments, before any work."""
    check(profile, only, jobs)
    names = set(filter(None, only.split(",")))
    lay = Layout.of(PROFILES[profile], Path(out or default_out(profile)).resolve(), train)
    plan = build_plan(PROFILES[profile], lay, names or None, train, reuse, jobs)
    t0 = time.perf_counter()
    run_plan(plan, jobs)
    print(write_outputs(lay, PROFILES[profile]))
    failed = [s for s in plan.steps if s.failed]
    print(f"wrote {lay.out / 'tables.md'} (.csv, .tex, figures/) in {time.perf_counter() - t0:.0f} s; "
          f"{len(plan.steps) - len(failed)}/{len(plan.steps)} steps ok")
    return 1 if failed else 0
