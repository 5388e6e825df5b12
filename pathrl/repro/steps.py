"""The steps of a reproduction (:mod:`pathrl.repro.plan`): each runs one of the project's commands in the checkout,
its console output in ``<out>/logs/<step>.log``, and skips what ``--reuse`` keeps.

Evaluations run ``pathrl-eval`` (every task family: :mod:`pathrl.families`), one per step or several in one
``pathrl-eval batch=FILE`` process (:func:`evaluate_batch`: the imports and PyBullet ball scenes built once),
TOPP-RA ``pathrl-toppra``, the motion-profile tables ``pathrl-industrial``; the TrueAdapt table's limit validation
and time per decision run the TrueAdapt family's registry steps (``python -m pathrl.cli.family_step``). A result
records the SHA-256 of what it was made from (:mod:`pathrl.repro.inputs`): ``--reuse`` re-evaluates a result whose
inputs changed.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import yaml

from pathrl.models import model_path
from pathrl.repro import trueadapt as adapt
from pathrl.repro.inputs import fingerprint, record, stale
from pathrl.repro.layout import ROOT, Layout, Profile, rel
from pathrl.repro.tables import CONTROLLER_MODELS, WARM_STARTS, Baseline, Evaluation, warm_chain

__all__ = ["BIN", "INDUSTRIAL", "EvalJob", "StepFailed", "adapt_job", "adapt_step", "dataset_seed",
           "eval_job", "evaluate", "evaluate_batch", "industrial", "kept", "path_change", "path_change_file", "program",
           "realtime", "sh", "shipped", "tiny_dataset", "toppra", "train_and_ship", "training_jobs"]

#: The project's console scripts (pathrl-eval, pathrl-toppra, ...): beside the Python running this.
BIN = Path(sys.executable).parent


class StepFailed(RuntimeError):
    """A step's command failed: the exit code and the last line of its log."""


def sh(cmd: list[str], log: Path) -> None:
    """Run a command in the checkout with its output in `log`; raise StepFailed with the log's last line on
    failure."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        rc = subprocess.run(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT,
                            env=dict(os.environ, OMP_NUM_THREADS="1")).returncode
    if rc != 0:
        lines = [ln for ln in log.read_text().splitlines() if ln.strip()]
        raise StepFailed(f"exit {rc}: {lines[-1] if lines else ''} (log: {log})")


def program(cmd: list[str]) -> list[str]:
    """`cmd` with its program resolved: ``python`` is the project's Python, anything else one of its console
    scripts (:data:`BIN`)."""
    return [sys.executable if cmd[0] == "python" else str(BIN / cmd[0]), *cmd[1:]]


def kept(result: Path, inputs: dict[str, str], reuse: bool, label: str) -> bool:
    """Whether --reuse keeps `result` (made from `inputs`: pathrl.repro.inputs.stale); when its inputs changed,
    the console says it is re-evaluated."""
    why = stale(result, inputs) if reuse else "no --reuse"
    if reuse and why is not None and why != "no result":
        print(f"{label}: {why}: re-evaluating", flush=True)
    return why is None


def shipped(e: Evaluation, lay: Layout) -> bool:
    """Whether the policy of ``e`` is shipped (rows of policies that are not show a dash)."""
    model = model_path(e.model, lay.models)
    controller = e.model in CONTROLLER_MODELS and (model / "config.yaml").is_file()  # evaluated, never trained
    return (model / "model.pt").is_file() or any(model.glob("model_*.pt")) or controller


@dataclass(frozen=True)
class EvalJob:
    """One ``pathrl-eval`` of a step: its arguments (key=value), its ``metrics.json`` and the inputs it records."""

    args: list[str]
    result: Path
    inputs: dict[str, str]


def eval_job(e: Evaluation, profile: Profile, lay: Layout, reuse: bool) -> EvalJob | None:
    """The ``pathrl-eval`` of a shipped policy on its test split into ``raw/<id>/`` (None: not shipped, or kept)."""
    model = model_path(e.model, lay.models)
    raw = lay.out / "raw" / e.id
    if not shipped(e, lay):
        return None
    # the model's files, those of the policy its controller config names, and the test split (pathrl/repro/inputs.py);
    # a result without recorded inputs (made before they were recorded) is kept, its next evaluation records them
    inputs = fingerprint(ROOT, model, lay.test_data / e.data_robot / e.test_dir)
    if kept(raw / "metrics.json", inputs, reuse, e.id):
        return None
    data = rel(lay.test_data / e.data_robot / e.test_dir)
    args = [f"run_dir={rel(model)}", f"dataset.path={data}", f"segments={e.segments}", "seed=0",
            f"out={raw}"]  # eager limits (pathrl-eval's default: faster here)
    if profile.episodes is not None:
        args.append(f"episodes={profile.episodes}")
    elif e.episodes is not None:
        args.append(f"episodes={e.episodes}")
    if e.task:
        args += [f"task={e.task}", "backend=pybullet"]
    if e.open_loop:
        args.append("open_loop=true")
    return EvalJob(args, raw / "metrics.json", inputs)


def adapt_job(a: adapt.AdaptEval, profile: Profile, lay: Layout, reuse: bool) -> EvalJob | None:
    """A TrueAdapt evaluation (``pathrl-eval`` of its model directory; None: the model or the split is missing, or
    the result is kept)."""
    result = lay.out / "raw" / a.id / "metrics.json"
    data = ROOT / ("datasets" if a.split == "test" else "data") / adapt.ROBOT / a.dataset
    inputs = fingerprint(ROOT, model_path(a.run), data)
    cmd = adapt.eval_command(a, ROOT, lay.out / "raw", profile.episodes or adapt.EPISODES,
                             kept(result, inputs, reuse, a.id))
    return None if cmd is None else EvalJob(cmd[1:], result, inputs)


def _run_one(job: EvalJob | None, log: Path) -> None:
    """Run `job` alone (None: nothing to do) and record its inputs."""
    if job is not None:
        sh(program(["pathrl-eval", *job.args]), log)
        record(job.result, job.inputs)


def evaluate(e: Evaluation, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    """``pathrl-eval`` of a shipped policy on its test split into ``raw/<id>/``, its inputs recorded beside it."""
    _run_one(eval_job(e, profile, lay, reuse), logs / f"eval_{e.id}.log")


def evaluate_batch(name: str, jobs: list[Callable[[], EvalJob | None]], logs: Path) -> None:
    """The evaluations `jobs` make (each called now: what is kept is decided when the step runs) in one
    ``pathrl-eval batch=FILE`` process (shared imports and PyBullet ball scenes); every result written is recorded
    with its inputs, also when another line of the batch failed (then StepFailed)."""
    todo = [j for make in jobs if (j := make()) is not None]
    if not todo:
        return
    logs.mkdir(parents=True, exist_ok=True)
    batch = logs / f"batch_{name}.txt"
    batch.write_text("".join(shlex.join(j.args) + "\n" for j in todo))
    start = time.time()
    try:
        sh(program(["pathrl-eval", f"batch={batch}"]), logs / f"batch_{name}.log")
    finally:
        for j in todo:
            if j.result.is_file() and j.result.stat().st_mtime >= start:
                record(j.result, j.inputs)


def toppra(b: Baseline, profile: Profile, lay: Layout, reuse: bool, logs: Path, workers: int) -> None:
    """``pathrl-toppra`` (with Ruckig) on a row's split, knots and episode plan into ``raw/<id>.json``."""
    out = lay.out / "raw" / f"{b.id}.json"
    if reuse and out.is_file():
        return
    cmd = [str(BIN / "pathrl-toppra"), f"robot={b.robot}", f"dataset.path={lay.test_data / b.robot / b.dataset}",
           f"knots={b.knots}", f"segments={b.segments}", "seed=0", f"workers={workers}", f"out={out}", "ruckig=true"]
    if profile.episodes is not None:
        cmd.append(f"episodes={profile.episodes}")
    sh(cmd, logs / f"{b.id}.log")


#: The motion-profile tables of the third paper (`pathrl-industrial`, docs/industrial.md): (subcommand, output key,
#: file in the output dir, overrides). The shipped TD3 policies are evaluated; MPGD and bisection run in full.
INDUSTRIAL = (("table2", "out_table2", "industrial_table2.md", ("policy=models/industrial/industrial_td3",)),
              ("table2", "out_table2", "industrial_table2_noise.md",
               ("policy=models/industrial/industrial_td3", "controller.noise_mm=0.05", "controller.runs=5",
                "seed_runs=[]")),
              ("validate", "out_validation", "industrial_validation.md", ()),
              ("timing", "out_timing", "industrial_timing.md", ("policy=models/industrial/industrial_td3",)),
              ("speed", "out_speed", "industrial_speed.md", ()),
              ("speed", "out_speed", "industrial_speed_rl.md", ("policy=models/industrial/industrial_td3",)),
              ("table4", "out_table4", "industrial_table4.md", ()),
              ("sweep", "out_sweep", "industrial_baseline_sweep.md", ("sweep_speeds=[100,250,400,700,1100]",)))


def industrial(lay: Layout, reuse: bool, logs: Path) -> None:
    """The motion-profile tables (`INDUSTRIAL`), each written by pathrl-industrial into the output dir."""
    for command, key, name, overrides in INDUSTRIAL:
        out = lay.out / name
        if reuse and out.is_file():
            continue
        shown = rel(out)  # as the table's "Measured with" line
        sh([str(BIN / "pathrl-industrial"), command, *overrides, f"{key}={shown}"], logs / f"industrial_{out.stem}.log")


def adapt_step(cmd: list[str] | None, log: Path) -> None:
    """Run a TrueAdapt registry step's command (:func:`pathrl.repro.trueadapt.validation_command`,
    :func:`~pathrl.repro.trueadapt.realtime_command`; None: nothing to do)."""
    if cmd is not None:
        sh(program(cmd), log)


def realtime(key: str, robot: str, split: str, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    """Table IX's real-time measurement of `robot` on `split` into ``raw/realtime_<key>.json``."""
    out = lay.out / "raw" / f"realtime_{key}.json"
    if reuse and out.is_file():
        return
    episodes = 5 if profile.name == "quick" else 20
    sh([sys.executable, "-m", "pathrl.eval.realtime", robot, str(lay.test_data / split), str(out),
        "--episodes", str(episodes), *([] if profile.compile_limits else ["--eager"])], logs / f"realtime_{key}.log")


def path_change_file(lay: Layout, key: str) -> Path:
    """The result of the path changes of `key` (``robot/split``)."""
    return lay.out / "raw" / f"path_change_{key.replace('/', '_')}.json"


def path_change(key: str, model: str, split: str, profile: Profile, lay: Layout, reuse: bool, logs: Path) -> None:
    """The path changes of a shipped `model` on `split` (skipped when it is not shipped), its inputs recorded."""
    out = path_change_file(lay, key)
    model_dir = model_path(model, lay.models)
    if not (model_dir / "model.pt").is_file():
        return
    inputs = fingerprint(ROOT, model_dir, lay.test_data / split)
    if kept(out, inputs, reuse, f"path changes {key}"):
        return
    episodes = 10 if profile.name == "quick" else 200
    sh([sys.executable, "-m", "pathrl.eval.path_change", str(model_dir), str(lay.test_data / split),
        str(out), "--episodes", str(episodes)], logs / f"{out.stem}.log")
    record(out, inputs)


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
    """Train (resume) `model` on the robot and dataset of `e` (generated first if missing) and ship it to
    ``<models>/<family>/<model>``."""
    from pathrl.train.ship import ship

    data = lay.train_data / e.data_robot / e.dataset
    if not (data / "train.npz").is_file():
        sh([str(BIN / "pathrl-dataset"), "generate", f"robot={e.data_robot}", f"dataset={e.dataset}",
            f"dataset.num_train={profile.num_train}", f"dataset.num_test={profile.num_test}",
            f"dataset.path={data}"], logs / f"dataset_{e.data_robot}_{e.dataset}.log")
    run_dir = lay.runs / model / "seed0"
    warm = [f"init_from={model_path(WARM_STARTS[model], lay.models)}"] if model in WARM_STARTS else []
    sh([str(BIN / "pathrl-train"), f"+experiment={model}", "resume=true", f"run_dir={run_dir}",
        f"dataset.path={data}", f"compile_limits={str(profile.compile_limits).lower()}", *profile.train_overrides,
        *warm], logs / f"train_{model}.log")
    ship(run_dir, model_path(model, lay.models))
