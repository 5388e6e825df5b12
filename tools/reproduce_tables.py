"""`make reproduce-tables`: the paper's Tables I-VI from shipped policies and TOPP-RA, next to the published values.

Every evaluation (a shipped policy on a test split) and every TOPP-RA baseline (the same split, knots and
episode plan) runs once, even when several table rows use it. Outputs (written atomically):
results/tables.md, tables.csv, tables.tex, figures/*.png, raw/<evaluation>/metrics.json, raw/<toppra>.json;
a policy's evaluation also writes the SHA-256 of its model and test split beside its result (raw/<evaluation>/
inputs.json, pathrl/repro/inputs.py): --reuse re-evaluates a result whose inputs changed. Each step's console
output goes to results/logs/<step>.log. The TrueAdapt paper's Table I (pathrl/repro/trueadapt.py):
its shipped policies and controllers on the committed test splits, the ball in PyBullet, and the 10^5-trajectory
limit validation (raw/trueadapt_validation.json); --only takes their names too (e.g. trueadapt_validation).
The rows are sweeps/<table>.yaml (pathrl/repro/sweeps.py); --only also takes a table's file name (`make table
T=II` is --only table_II): its rows are evaluated, every table is rendered from the results in --out.

Profiles:
  full   1200 paper segments per evaluation on the committed test splits (datasets/), policies from models/.
  quick  12 episodes; with --train: tiny generated datasets and tiny trainings under results/quick/ (tests the
         whole pipeline in a few minutes; the numbers mean nothing).
--train (TRAIN=1) trains every policy first (`pathrl-train +experiment=<model> resume=true`, budgets in
conf/experiment/*.yaml; rerun to resume after an interruption) and ships it to models/<model>.
Evaluations and TOPP-RA baselines run --jobs at a time (JOBS=N; default the CPU count, at most 8); the
real-time measurements of Table IX and the path changes run last, one at a time on the otherwise idle machine.

    tools/reproduce_tables.py [--profile full|quick] [--train] [--only MODEL,...] [--reuse] [--out DIR] [--jobs N]
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from pathrl.config.paper import load as load_paper  # noqa: E402
from pathrl.repro.sweeps import SweepsError  # noqa: E402

try:  # the rows are read from sweeps/<table>.yaml at import: a broken file is its one-line error
    from pathrl.repro import trueadapt as adapt
    from pathrl.repro.figures import CURVES, learning_curves, pareto_table_ii, path_overlay
    from pathrl.repro.render import render_latex, render_markdown
    from pathrl.repro.tables import (
        CONTROLLER_MODELS,
        PATH_CHANGE,
        REALTIME,
        ROWS,
        SWEEPS,
        WARM_STARTS,
        Baseline,
        Evaluation,
        baselines,
        evaluations,
        select,
        training_record,
        warm_chain,
    )
except SweepsError as exc:
    sys.exit(f"error: {exc}")
from pathrl.repro.inputs import fingerprint, record, stale  # noqa: E402
from pathrl.storage import atomic_write  # noqa: E402
from pathrl.train.ship import read_curve  # noqa: E402

BIN = Path(sys.executable).parent
#: The paper's tables (pathrl/config/paper/tracking.yaml), as the renderers take them.
PAPER = load_paper("tracking").as_dict()
#: Evaluations whose episodes are drawn as example path overlays (one per robot).
OVERLAYS = {"iiwa7_random_track_distill": "KUKA iiwa 7, random path",
            "armar6_random_track_distill": "ARMAR-6, random path", "armar4_random": "ARMAR-4 (fixed base), random path"}


@dataclass(frozen=True)
class Profile:
    name: str
    episodes: int | None  # paper segments per evaluation (None: the CLIs' default, 1200)
    num_train: int  # paths of generated datasets (--train)
    num_test: int
    train_overrides: tuple[str, ...] = ()
    compile_limits: bool = True  # torch.compile the limit kernels in trainings and real-time measurements


PROFILES = {
    "full": Profile("full", None, 1000, 200),
    "quick": Profile("quick", 12, 12, 4, ("iterations=2", "env.num_envs=64", "agent.num_steps_per_env=8",
                                          "agent.save_interval=1", "threads=1"), compile_limits=False),
}


@dataclass
class Layout:
    """Where a profile reads and writes."""

    out: Path
    models: Path
    runs: Path
    test_data: Path  # <robot>/<dataset> test splits
    train_data: Path  # <robot>/<dataset> datasets with a train split (--train)

    @classmethod
    def of(cls, profile: Profile, out: Path, train: bool) -> Layout:
        if profile.name == "quick" and train:  # self-contained: tiny datasets, runs and models under out/
            return cls(out, out / "models", out / "runs", out / "data", out / "data")
        return cls(out, ROOT / "models", ROOT / "runs", ROOT / "datasets", ROOT / "data")


#: Phases of a plan, in order. Steps of a phase named in CONCURRENT run ``--jobs`` at a time (independent
#: evaluations, one process each); the others run one at a time: trainings (never two on 2 cores) and the
#: real-time measurements of Table IX (they time computation, so they run on an otherwise idle machine).
PHASES = ("prepare", "evaluate", "timing")
CONCURRENT = {"evaluate"}


@dataclass
class Step:
    label: str
    run: Callable[[], None]
    phase: str
    failed: str | None = None
    seconds: float = 0.0


@dataclass
class Plan:
    steps: list[Step] = field(default_factory=list)

    def add(self, phase: str, label: str, fn: Callable[[], None]) -> None:
        assert phase in PHASES, phase
        self.steps.append(Step(label, fn, phase))

    def phase(self, name: str) -> list[Step]:
        return [s for s in self.steps if s.phase == name]


class StepFailed(RuntimeError):
    pass


def sh(cmd: list[str], log: Path) -> None:
    """Run a command with its output in `log`; raise StepFailed with the log's last line on failure."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        rc = subprocess.run(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                            env=dict(os.environ, OMP_NUM_THREADS="1")).returncode
    if rc != 0:
        lines = [ln for ln in log.read_text().splitlines() if ln.strip()]
        raise StepFailed(f"exit {rc}: {lines[-1] if lines else ''} (log: {log})")


def build_plan(args: argparse.Namespace, profile: Profile, lay: Layout) -> Plan:
    only = set(args.only.split(",")) if args.only else None
    rows = select(only)
    evals, bases = evaluations(rows), baselines(rows)
    logs = lay.out / "logs"
    plan = Plan()
    if args.train:
        needed = {(e.data_robot, e.dataset, e.test_dir) for e in evals}
        if profile.name == "quick":
            for robot, name, test_dir in sorted(needed):
                plan.add("prepare", f"dataset {robot}/{test_dir}", lambda robot=robot, name=name, test_dir=test_dir:
                         tiny_dataset(robot, name, test_dir, profile, lay, args.reuse, logs))
        for model, e in training_jobs(evals).items():
            plan.add("prepare", f"train {model}", lambda model=model, e=e: train_and_ship(model, e, profile, lay, logs))
    # The simulated (PyBullet) evaluations, the longest steps, first: the concurrent phase then ends with
    # short steps on every lane.
    for e in sorted(evals, key=lambda e: not e.task):
        plan.add("evaluate", f"evaluate {e.id}", lambda e=e: evaluate(e, profile, lay, args.reuse, logs))
    toppra_workers = 1 if args.jobs > 1 else 2
    for b in bases:
        plan.add("evaluate", f"TOPP-RA {b.robot}/{b.dataset} ({b.segments})",
                 lambda b=b: toppra(b, profile, lay, args.reuse, logs, toppra_workers))
    for a in adapt.evaluations(only):  # TrueAdapt Table I (the ball in PyBullet), then its limit validation
        plan.add("evaluate", f"evaluate {a.id}", lambda a=a: adapt_evaluate(a, profile, lay, args.reuse, logs))
    if only is None or adapt.VALIDATION_ID in only:
        n = 1000 if profile.name == "quick" else 100_000
        plan.add("evaluate", "TrueAdapt limit validation", lambda: run_script(adapt.validation_command(
            ROOT, lay.out / "raw", n, args.reuse), logs / f"{adapt.VALIDATION_ID}.log"))
        plan.add("timing", "TrueAdapt time per decision", lambda: run_script(adapt.realtime_command(
            ROOT, lay.out / "raw", lay.models, lay.test_data, 2000, args.reuse), logs / f"{adapt.REALTIME_ID}.log"))
    if only is None:
        for key, robot, split in REALTIME:
            plan.add("timing", f"real time {key}", lambda key=key, robot=robot, split=split: realtime(
                key, robot, split, profile, lay, args.reuse, logs))
        plan.add("evaluate", "motion-profile tables (pathrl-industrial)", lambda: industrial(lay, args.reuse, logs))
        for key, model, split in PATH_CHANGE:  # times re-plans: on the otherwise idle machine, like Table IX
            plan.add("timing", f"path changes {key}", lambda key=key, model=model, split=split: path_change(
                key, model, split, profile, lay, args.reuse, logs))
    return plan


#: The motion-profile tables of the third paper (`pathrl-industrial`, docs/industrial.md): (subcommand, output key,
#: file in the output dir, overrides). The shipped TD3 policies are evaluated; MPGD and bisection run in full.
INDUSTRIAL = (("table2", "out_table2", "industrial_table2.md", ("policy=models/industrial_td3",)),
              ("table2", "out_table2", "industrial_table2_noise.md",
               ("policy=models/industrial_td3", "controller.noise_mm=0.05", "controller.runs=5", "seed_runs=[]")),
              ("validate", "out_validation", "industrial_validation.md", ()),
              ("timing", "out_timing", "industrial_timing.md", ("policy=models/industrial_td3",)),
              ("speed", "out_speed", "industrial_speed.md", ()),
              ("speed", "out_speed", "industrial_speed_rl.md", ("policy=models/industrial_td3",)),
              ("table4", "out_table4", "industrial_table4.md", ()),
              ("sweep", "out_sweep", "industrial_baseline_sweep.md", ("sweep_speeds=[100,250,400,700,1100]",)))


def industrial(lay: Layout, reuse: bool, logs: Path) -> None:
    """The motion-profile tables (`INDUSTRIAL`), each written by pathrl-industrial into the output dir."""
    for command, key, name, overrides in INDUSTRIAL:
        out = lay.out / name
        if reuse and out.is_file():
            continue
        shown = out.relative_to(ROOT) if out.is_relative_to(ROOT) else out  # as the table's "Measured with" line
        sh([str(BIN / "pathrl-industrial"), command, *overrides, f"{key}={shown}"], logs / f"industrial_{out.stem}.log")


def kept(result: Path, inputs: dict[str, str], reuse: bool, label: str) -> bool:
    """Whether --reuse keeps `result` (made from `inputs`: pathrl.repro.inputs.stale); when its inputs changed,
    the console says it is re-evaluated."""
    why = stale(result, inputs) if reuse else "no --reuse"
    if reuse and why is not None and why != "no result":
        print(f"{label}: {why}: re-evaluating", flush=True)
    return why is None


def adapt_evaluate(a: adapt.AdaptEval, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    """A TrueAdapt evaluation (skipped when its model or split is missing), its inputs recorded beside it."""
    result = lay.out / "raw" / a.id / "metrics.json"
    data = ROOT / ("datasets" if a.split == "test" else "data") / adapt.ROBOT / a.dataset
    inputs = fingerprint(ROOT, None if a.model is None else ROOT / "models" / a.model, data)
    cmd = adapt.eval_command(a, ROOT, lay.out / "raw", profile.episodes or adapt.EPISODES,
                             kept(result, inputs, reuse, a.id))
    run_script(cmd, logs / f"eval_{a.id}.log")
    if cmd is not None:
        record(result, inputs)


def run_script(cmd: list[str] | None, log: Path) -> None:
    """Run a tools/ script with the project's Python (None: nothing to do)."""
    if cmd is not None:
        sh([sys.executable, *cmd], log)


def tiny_dataset(robot: str, name: str, test_dir: str, profile: Profile, lay: Layout, reuse: bool,
                 logs: Path) -> None:
    """A quick profile's generated dataset `<robot>/<test_dir>`; a second test split (`test_dir` is not the
    dataset's name) holds only test paths, from the generator's next seed."""
    dest = lay.train_data / robot / test_dir
    if reuse and (dest / "dataset.json").is_file():
        return
    split = ([f"dataset.num_train={profile.num_train}"] if test_dir == name else
             ["dataset.num_train=0", f"dataset.seed={dataset_seed(name) + 1}"])
    sh([str(BIN / "pathrl-dataset"), "generate", f"robot={robot}", f"dataset={name}", *split,
        f"dataset.num_test={profile.num_test}", f"dataset.path={dest}", "overwrite=true"],
       logs / f"dataset_{robot}_{test_dir}.log")


def dataset_seed(name: str) -> int:
    """The generator seed of ``conf/dataset/<name>.yaml``."""
    return int(yaml.safe_load((ROOT / "conf" / "dataset" / f"{name}.yaml").read_text()).get("seed", 0))


def realtime(key: str, robot: str, split: str, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    out = lay.out / "raw" / f"realtime_{key}.json"
    if reuse and out.is_file():
        return
    episodes = 5 if profile.name == "quick" else 20
    sh([sys.executable, "-m", "pathrl.eval.realtime", robot, str(lay.test_data / split), str(out),
        "--episodes", str(episodes), *([] if profile.compile_limits else ["--eager"])], logs / f"realtime_{key}.log")


def path_change_file(lay: Layout, key: str) -> Path:
    return lay.out / "raw" / f"path_change_{key.replace('/', '_')}.json"


def path_change(key: str, model: str, split: str, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    out = path_change_file(lay, key)
    if not (lay.models / model / "model.pt").is_file():
        return
    inputs = fingerprint(ROOT, lay.models / model, lay.test_data / split)
    if kept(out, inputs, reuse, f"path changes {key}"):
        return
    episodes = 10 if profile.name == "quick" else 200
    sh([sys.executable, "-m", "pathrl.eval.path_change", str(lay.models / model), str(lay.test_data / split),
        str(out), "--episodes", str(episodes)], logs / f"{out.stem}.log")
    record(out, inputs)


def training_jobs(evals: list[Evaluation]) -> dict[str, Evaluation]:
    """{model: the evaluation whose robot and dataset it trains on} for --train, a warm start's sources before it.
    Controllers and second-test-set rows train nothing; a generalization row trains on its ``train_dataset`` (none
    given: its policy is trained by another row)."""
    trained: dict[str, Evaluation] = {}
    for e in evals:
        if e.generalization and e.train_dataset:
            e = replace(e, dataset=e.train_dataset, generalization=False, train_dataset=None)
        if e.generalization or e.second_test_set or e.model in CONTROLLER_MODELS:
            continue
        for source in warm_chain(e.model):  # a warm start's sources first: it starts from their shipped weights
            trained.setdefault(source, replace(e, model=source))
        trained.setdefault(e.model, e)
    return trained


def train_and_ship(model: str, e: Evaluation, profile: Profile, lay: Layout, logs: Path) -> None:
    from pathrl.train.ship import ship

    data = lay.train_data / e.data_robot / e.dataset
    if not (data / "train.npz").is_file():
        sh([str(BIN / "pathrl-dataset"), "generate", f"robot={e.data_robot}", f"dataset={e.dataset}",
            f"dataset.num_train={profile.num_train}", f"dataset.num_test={profile.num_test}",
            f"dataset.path={data}"], logs / f"dataset_{e.data_robot}_{e.dataset}.log")
    run_dir = lay.runs / model / "seed0"
    warm = [f"init_from={lay.models / WARM_STARTS[model]}"] if model in WARM_STARTS else []
    sh([str(BIN / "pathrl-train"), f"+experiment={model}", "resume=true", f"run_dir={run_dir}",
        f"dataset.path={data}", f"compile_limits={str(profile.compile_limits).lower()}", *profile.train_overrides,
        *warm], logs / f"train_{model}.log")
    ship(run_dir, lay.models / model)


def shipped(e: Evaluation, lay: Layout) -> bool:
    """Whether the policy of ``e`` is shipped (rows of policies that are not show a dash)."""
    model = lay.models / e.model
    controller = e.model in CONTROLLER_MODELS and (model / "config.yaml").is_file()  # evaluated, never trained
    return (model / "model.pt").is_file() or any(model.glob("model_*.pt")) or controller


def rel(path: Path) -> Path:
    """`path` relative to the repository (the commands' working directory) when inside it: results record
    the paths they were made from, and the committed ones should not name one machine's checkout."""
    try:
        return path.relative_to(ROOT)
    except ValueError:
        return path


def evaluate(e: Evaluation, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    model = lay.models / e.model
    raw = lay.out / "raw" / e.id
    if not shipped(e, lay):
        return
    # the model's files, those of the policy its controller config names, and the test split (pathrl/repro/inputs.py);
    # a result without recorded inputs (made before they were recorded) is kept, its next evaluation records them
    inputs = fingerprint(ROOT, model, lay.test_data / e.data_robot / e.test_dir)
    if kept(raw / "metrics.json", inputs, reuse, e.id):
        return
    data = rel(lay.test_data / e.data_robot / e.test_dir)
    cmd = [str(BIN / "pathrl-eval"), f"run_dir={rel(model)}", f"dataset.path={data}",
           f"segments={e.segments}", "seed=0", f"out={raw}"]  # eager limits (pathrl-eval's default: faster here)
    if profile.episodes is not None:
        cmd.append(f"episodes={profile.episodes}")
    elif e.episodes is not None:
        cmd.append(f"episodes={e.episodes}")
    if e.task:
        cmd += [f"task={e.task}", "backend=pybullet"]
    if e.open_loop:
        cmd.append("open_loop=true")
    sh(cmd, logs / f"eval_{e.id}.log")
    record(raw / "metrics.json", inputs)


def toppra(b: Baseline, profile: Profile, lay: Layout, reuse: bool, logs: Path, workers: int) -> None:
    out = lay.out / "raw" / f"{b.id}.json"
    if reuse and out.is_file():
        return
    cmd = [str(BIN / "pathrl-toppra"), f"robot={b.robot}", f"dataset.path={lay.test_data / b.robot / b.dataset}",
           f"knots={b.knots}", f"segments={b.segments}", "seed=0", f"workers={workers}", f"out={out}", "ruckig=true"]
    if profile.episodes is not None:
        cmd.append(f"episodes={profile.episodes}")
    sh(cmd, logs / f"{b.id}.log")


def collect(lay: Layout) -> dict:
    """Load every metrics.json of a shipped policy and every TOPP-RA report of this output directory (an
    evaluation of a policy that was since removed from ``models/`` is not shown)."""
    res: dict = {"evaluations": {}, "baselines": {}}
    for e in evaluations():
        p = lay.out / "raw" / e.id / "metrics.json"
        if shipped(e, lay) and p.is_file():
            res["evaluations"][e.id] = json.loads(p.read_text())
    for b in baselines():
        p = lay.out / "raw" / f"{b.id}.json"
        if p.is_file():
            res["baselines"][b.id] = json.loads(p.read_text())
    res["training"] = {}
    for model in dict.fromkeys(m for e in evaluations() for m in (*warm_chain(e.model), e.model)):
        if (record := training_record(lay.models / model)) is not None:
            res["training"][model] = record
    res["path_change"] = {}
    for key, _, _ in PATH_CHANGE:
        p = path_change_file(lay, key)
        if p.is_file():
            res["path_change"][key] = json.loads(p.read_text())
    res["realtime"] = {}
    for key, _, _ in REALTIME:
        p = lay.out / "raw" / f"realtime_{key}.json"
        if p.is_file():
            res["realtime"][key] = json.loads(p.read_text())
    res.update(adapt.collect(lay.out / "raw", ROOT / "models", ROOT / "results" / "trueadapt_from_scratch"))
    res["training"].update(res.pop("trueadapt_training"))
    return res


def write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, text)


def write_outputs(lay: Layout, profile: Profile) -> str:
    res = collect(lay)
    md, rows = render_markdown(res, PAPER, profile.name)
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    write_atomic(lay.out / "tables.md", md)
    write_atomic(lay.out / "tables.csv", buf.getvalue())
    write_atomic(lay.out / "tables.tex", render_latex(res, PAPER))
    figs = lay.out / "figures"
    pareto_table_ii(res, PAPER, figs / "pareto_table_II.png")
    for eid, title in OVERLAYS.items():
        mcap = lay.out / "raw" / eid / "episodes.mcap"
        if eid in res["evaluations"] and mcap.is_file():
            path_overlay(mcap, res["evaluations"][eid], title, figs / f"paths_{eid}.png")
    for name, (title, models) in CURVES.items():
        files = {m: lay.models / m / "curve.csv" for m in models}
        curves = {m: read_curve(f) for m, f in files.items() if f.is_file()}
        learning_curves(curves, title, figs / f"learning_curve_{name}.png")
    return md


def run_plan(plan: Plan, jobs: int) -> None:
    """Run the plan's phases in order with a progress bar; a failed step is reported and does not stop the
    others (its rows show a dash)."""
    from concurrent.futures import ThreadPoolExecutor
    from threading import Lock

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    running: list[str] = []
    lock = Lock()
    with Progress(TextColumn("[bold]reproduce-tables"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.description}")) as bar:
        task = bar.add_task("", total=len(plan.steps))

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

        for phase in PHASES:
            steps = plan.phase(phase)
            if phase in CONCURRENT and jobs > 1:
                with ThreadPoolExecutor(jobs) as pool:
                    list(pool.map(run, steps))
            else:
                for step in steps:
                    run(step)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", choices=sorted(PROFILES), default="full")
    ap.add_argument("--train", action="store_true", help="train (resume) every policy first, then ship it")
    ap.add_argument("--only", default="", help="comma-separated model or sweeps/ table names (table_II): only their "
                    "rows (the other tables render from the results already in --out)")
    ap.add_argument("--reuse", action="store_true", help="keep evaluation / TOPP-RA results already in --out")
    ap.add_argument("--out", default=None, help="output dir (default results/, quick: results/quick/)")
    ap.add_argument("--jobs", type=int, default=min(os.cpu_count() or 1, 8),
                    help="evaluations run at a time (default: the CPU count, at most 8)")
    args = ap.parse_args()
    profile = PROFILES[args.profile]
    if args.jobs < 1:
        sys.exit(f"error: --jobs must be >= 1, got {args.jobs}")
    out = Path(args.out) if args.out else ROOT / ("results" if profile.name == "full" else "results/quick")
    known = {r.evaluation.model for r in ROWS} | adapt.names() | set(SWEEPS)
    unknown = set(filter(None, args.only.split(","))) - known
    if unknown:
        sys.exit(f"error: --only: unknown model or table(s) {sorted(unknown)}; known: {sorted(known)}")
    lay = Layout.of(profile, out.resolve(), args.train)
    plan = build_plan(args, profile, lay)

    t0 = time.perf_counter()
    run_plan(plan, args.jobs)
    md = write_outputs(lay, profile)
    print(md)
    failed = [s for s in plan.steps if s.failed]
    print(f"wrote {lay.out / 'tables.md'} (.csv, .tex, figures/) in {time.perf_counter() - t0:.0f} s; "
          f"{len(plan.steps) - len(failed)}/{len(plan.steps)} steps ok")
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
