"""CLI fuzz, round three (issue 50): every entry point fed bad input. Each case must exit with code 2, print exactly
one line on stderr, no traceback, and leave nothing behind: no new or changed file or directory in the working
directory, the cases' inputs, models/ or datasets/.

    .venv/bin/python tools/cli_fuzz.py                  # run every case, print the table (docs/reliability.md)
    .venv/bin/python tools/cli_fuzz.py --only eval       # the cases whose name starts with a prefix

The CLIs whose ``main`` takes argv run in-process (their stderr and warnings captured); ``pathrl-train`` runs
in-process up to Hydra (its pre-check: a case that reaches Hydra counts as exit 0) or, for the cases found only by
the run itself, as a subprocess. ``tests/test_cli_fuzz.py`` runs the same table.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


@dataclass(frozen=True)
class Case:
    """One bad input: the program, its arguments (``{fix}``: the inputs' directory, ``{root}``: the checkout), the
    text its one line of stderr must hold, and whether it runs as a subprocess."""

    name: str
    program: str
    args: tuple[str, ...]
    expect: str
    subprocess: bool = False


@dataclass
class Outcome:
    """What a case did: the text its line must hold (paths filled in), exit code (None: an exception escaped),
    stderr lines, a traceback seen, what it left behind, its wall time (s)."""

    case: Case
    expect: str
    code: int | None
    lines: list[str] = field(default_factory=list)
    traceback: bool = False
    leftovers: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        """Exit 2, one line holding the expected text, no traceback, nothing left behind."""
        return (self.code == 2 and len(self.lines) == 1 and not self.traceback and not self.leftovers
                and self.expect in self.lines[0])


def _c(name: str, program: str, args: str, expect: str, sub: bool = False) -> Case:
    return Case(name, program, tuple(args.split("|")) if args else (), expect, sub)


EVAL, EXPORT, TOPPRA, DATASET, VIEW, IND = ("pathrl-eval", "pathrl-export", "pathrl-toppra", "pathrl-dataset",
                                            "pathrl-view", "pathrl-industrial")
ROBOT = "pathrl-robot"
TRAIN, TA_EVAL, TA_REC, TA_VAL = ("pathrl-train", "tools/trueadapt_eval.py", "tools/trueadapt_record.py",
                                  "tools/trueadapt_validation.py")
_T = "dataset.path={fix}/tiny|iterations=1|env.num_envs=8|compile_limits=false|run_dir={fix}/runs/t|"
_E = "episodes=2|record=false|dataset.path={root}/datasets/iiwa7/random|"
_P = "robot=iiwa7|dataset.path={fix}/tiny|episodes=1|"
_I = "rows=[\"Type 1 Easy\"]|mpgd.k_max=1|"

#: The fuzz table. Arguments are separated by ``|``.
CASES: tuple[Case, ...] = (
    _c("robot: no file", ROBOT, "check", "usage: pathrl-robot check FILE.yaml"),
    _c("robot: missing file", ROBOT, "check|{fix}/nope.yaml", "cannot read"),
    _c("robot: no urdf key", ROBOT, "check|{fix}/tiny/dataset.json", "robot.urdf is required"),
    _c("robot: unknown command", ROBOT, "frob", "unknown command 'frob'"),
    _c("train: gamma < 0", TRAIN, _T + "agent.algorithm.gamma=-3", "agent.algorithm.gamma must be a number in (0, 1]"),
    _c("train: lambda > 1", TRAIN, _T + "agent.algorithm.lam=1.5", "agent.algorithm.lam must be"),
    _c("train: learning rate not a number", TRAIN, _T + "agent.algorithm.learning_rate=abc",
       "agent.algorithm.learning_rate must be a number > 0, got 'abc'"),
    _c("train: clip 0", TRAIN, _T + "agent.algorithm.clip_param=0", "agent.algorithm.clip_param must be"),
    _c("train: epochs 0", TRAIN, _T + "agent.algorithm.num_learning_epochs=0", "must be an integer >= 1"),
    _c("train: hidden dims not a list", TRAIN, _T + "agent.actor.hidden_dims=abc",
       "agent.actor.hidden_dims must be a list of positive integers"),
    _c("train: hidden dim 0", TRAIN, _T + "agent.critic.hidden_dims=[256,0]", "agent.critic.hidden_dims must be"),
    _c("train: unknown activation", TRAIN, _T + "agent.actor.activation=swoosh", "agent.actor.activation must be"),
    _c("train: init_std 0", TRAIN, _T + "agent.actor.distribution_cfg.init_std=0", "init_std must be"),
    _c("train: unknown robot", TRAIN, _T + "robot=nope", "options of robot: armar4, armar4_legs, armar6, iiwa7"),
    _c("train: run_dir is a file", TRAIN, _T + "run_dir={fix}/afile", "run_dir={fix}/afile is a file"),
    _c("train: missing dataset (run)", TRAIN, _T.replace("{fix}/tiny", "{fix}/nope").replace(
        "{fix}/runs/t", "{fix}/new/runs/t") + "threads=1", "dataset directory not found", sub=True),
    _c("train: non-ASCII dataset path (run)", TRAIN, _T.replace("{fix}/tiny", "{fix}/dätä nöt here").replace(
        "{fix}/runs/t", "{fix}/new/rün") + "threads=1", "dätä nöt here: dataset directory not found", sub=True),
    _c("train: resume, config.yaml a list (run)", TRAIN, _T.replace("{fix}/runs/t", "{fix}/listrun")
       + "resume=true|threads=1", "expected a mapping of config groups, got list", sub=True),
    _c("eval: no summary.json", EVAL, _E + "run_dir={fix}/nosum|out={fix}/o", "summary.json is missing"),
    _c("eval: summary.json without knot_gap_norm", EVAL, _E + "run_dir={fix}/nogap|out={fix}/o",
       "has no knot_gap_norm"),
    _c("eval: out is a file", EVAL, _E + "run_dir={root}/models/tracking/iiwa7_random|out={fix}/afile", "is a file"),
    _c("eval: out under a file", EVAL, _E + "run_dir={root}/models/tracking/iiwa7_random|out={fix}/afile/o",
       "{fix}/afile is a file, not a directory"),
    _c("eval: out/episodes.mcap a directory", EVAL, "episodes=2|dataset.path={root}/datasets/iiwa7/random|"
       "run_dir={root}/models/tracking/iiwa7_random|out={fix}/evalout", "episodes.mcap is a directory"),
    _c("eval: out inside models/", EVAL,
       _E + "run_dir={root}/models/tracking/iiwa7_random|out={root}/models/tracking/iiwa7_random", "inside models/"),
    _c("eval: out unwritable (/proc)", EVAL, _E + "run_dir={root}/models/tracking/iiwa7_random|out=/proc/pathrl_eval",
       "cannot write in /proc"),
    _c("eval: write_models not a bool", EVAL, _E + "run_dir={root}/models/tracking/iiwa7_random|write_models=maybe",
       "write_models must be true or false"),
    _c("export: no summary.json", EXPORT, "run_dir={fix}/nosum|out={fix}/o", "summary.json is missing"),
    _c("export: summary.json without knot_gap_norm", EXPORT, "run_dir={fix}/nogap|out={fix}/o", "has no knot_gap_norm"),
    _c("export: out is a file", EXPORT, "run_dir={root}/models/tracking/iiwa7_random|out={fix}/afile", "is a file"),
    _c("export: out/actor.onnx a directory", EXPORT, "run_dir={root}/models/tracking/iiwa7_random|out={fix}/exportout",
       "actor.onnx is a directory"),
    _c("export: out unwritable (/proc)", EXPORT, "run_dir={root}/models/tracking/iiwa7_random|out=/proc/pathrl_export",
       "cannot write in /proc"),
    _c("toppra: out is a directory", TOPPRA, _P + "out={fix}/adir", "out={fix}/adir is a directory"),
    _c("toppra: out under a file", TOPPRA, _P + "out={fix}/afile/t.json", "{fix}/afile is a file"),
    _c("toppra: out unwritable (/proc)", TOPPRA, _P + "out=/proc/pathrl_toppra.json", "cannot write in /proc"),
    _c("toppra: unknown robot", TOPPRA, "robot=nope", "options of robot: armar4, armar4_legs, armar6, iiwa7"),
    _c("toppra: non-ASCII dataset path", TOPPRA, "robot=iiwa7|dataset.path={fix}/dätä", "dätä: dataset directory"),
    _c("dataset: import, huge coefficients", DATASET, "import|--format|kiemel-json|--robot|iiwa7|{fix}/kie_huge|"
       "{fix}/imported", "beyond 100 rad"),
    _c("dataset: import onto an existing dataset", DATASET, "import|--format|kiemel-json|--robot|iiwa7|"
       "{fix}/kie_huge|{fix}/tiny", "pass --overwrite to replace it"),
    _c("dataset: import DEST under a file", DATASET, "import|--format|kiemel-json|--robot|iiwa7|{fix}/kie_huge|"
       "{fix}/afile/d", "{fix}/afile is a file"),
    _c("dataset: generate into a file", DATASET, "generate|robot=iiwa7|dataset.path={fix}/afile",
       "dataset.path={fix}/afile is a file"),
    _c("dataset: generate, unknown robot", DATASET, "generate|robot=nope", "options of robot:"),
    _c("dataset: generate, non-ASCII path into a file", DATASET, "generate|robot=iiwa7|dataset.path={fix}/afile/dä",
       "{fix}/afile is a file"),
    _c("view: --save onto a directory", VIEW, "{fix}/ep/episodes.mcap|--save|{fix}/adir", "is a directory"),
    _c("view: --save under a file", VIEW, "{fix}/ep/episodes.mcap|--save|{fix}/afile/x.rrd", "is a file"),
    _c("view: --save unwritable (/proc)", VIEW, "{fix}/ep/episodes.mcap|--save|/proc/pathrl_view.rrd",
       "cannot write in /proc"),
    _c("view: default output is a directory", VIEW, "{fix}/ep/episodes.mcap|--worst|2", "is a directory"),
    _c("view: truncated MCAP", VIEW, "{fix}/trunc/episodes.mcap", "truncated or damaged MCAP"),
    _c("view: --worst 0", VIEW, "{fix}/ep/episodes.mcap|--worst|0", "--worst must be >= 1"),
    _c("industrial: empty speed list", IND, "sweep|sweep_speeds=[]|out_sweep={fix}/s.md", "sweep_speeds must be"),
    _c("industrial: negative speed", IND, "sweep|sweep_speeds=[250,-1]|out_sweep={fix}/s.md", "sweep_speeds must be"),
    _c("industrial: NaN speed", IND, "sweep|sweep_speeds=[nan]|out_sweep={fix}/s.md",
       "sweep_speeds[0] must be a finite number"),
    _c("industrial: NaN feedback gain", IND, "table2|" + _I + "policy=feedback:nan|out_table2={fix}/t.md",
       "feedback gain must be a finite number"),
    _c("industrial: NaN controller value", IND, "sweep|controller.noise_mm=nan|out_sweep={fix}/s.md",
       "controller.noise_mm must be a finite number"),
    _c("industrial: out is a directory", IND, "sweep|out_sweep={fix}/adir", "out_sweep={fix}/adir is a directory"),
    _c("industrial: out under a file", IND, "table2|" + _I + "out_table2={fix}/afile/t.md", "{fix}/afile is a file"),
    _c("industrial: out unwritable (/proc)", IND, "table2|" + _I + "out_table2=/proc/pathrl_t2.md",
       "cannot write in /proc"),
    _c("industrial: record out is a file", IND, "record|traj=Type 1 Easy|method=mpgd|out={fix}/afile",
       "out={fix}/afile is a file"),
    _c("industrial: train run_dir is a file", IND, "train|run_dir={fix}/afile", "run_dir={fix}/afile is a file"),
    _c("industrial: waypoints 1", IND, "sweep|waypoints=1|out_sweep={fix}/s.md", "waypoints must be >= 2"),
    _c("trueadapt eval: 0 episodes", TA_EVAL, "--episodes|0", "--episodes must be >= 1"),
    _c("trueadapt eval: 0 envs", TA_EVAL, "--num-envs|0", "--num-envs must be >= 1"),
    _c("trueadapt eval: --out is a file", TA_EVAL, "--episodes|2|--out|{fix}/afile", "--out {fix}/afile is a file"),
    _c("trueadapt eval: unknown flag", TA_EVAL, "--bogus|2", "unrecognized arguments: --bogus 2"),
    _c("trueadapt eval: missing run", TA_EVAL, "--run|{fix}/nope", "run_dir not found"),
    _c("trueadapt record: --out is a file", TA_REC, "--controller|reference|--out|{fix}/afile", "is a file"),
    _c("trueadapt record: no source", TA_REC, "--out|{fix}/o", "one of the arguments --run --controller"),
    _c("trueadapt record: 0 episodes", TA_REC, "--controller|reference|--episodes|0|--out|{fix}/o",
       "--episodes must be >= 1"),
    _c("trueadapt validation: negative count", TA_VAL, "--trajectories|-1", "--trajectories must be >= 0"),
    _c("trueadapt validation: --out a directory", TA_VAL, "--trajectories|5|--out|{fix}/adir", "is a directory"),
    _c("trueadapt validation: joint out of range", TA_VAL, "--trajectories|2|--joint|9", "--joint must be in 0..6"),
)


# ---------------------------------------------------------------------------------------------------------------
# inputs


def _episode_json(knots, scale: float = 1.0) -> str:
    """An episode file in the authors' format (a natural cubic spline through `knots`), coefficients x `scale`."""
    import numpy as np
    from scipy.interpolate import make_interp_spline

    d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(knots, axis=0), axis=1))]
    u = d / d[-1]
    bs = make_interp_spline(u, knots, bc_type="natural")
    return json.dumps({"_b_spline": {"t": bs.t.tolist(), "c": (bs.c * scale).tolist(), "k": int(bs.k)},
                       "_u": u.tolist()})


def _model_copy(dest: Path, summary: dict | None) -> None:
    """models/tracking/iiwa7_random at `dest`, its summary.json replaced by `summary` (None: removed)."""
    shutil.copytree(ROOT / "models" / "tracking" / "iiwa7_random", dest)
    (dest / "summary.json").unlink()
    if summary is not None:
        (dest / "summary.json").write_text(json.dumps(summary))


def make_inputs(fix: Path) -> None:
    """The cases' inputs in `fix`: a tiny dataset, a file and a directory in wrong places, model copies without their
    length scale, a run whose config is a list, evaluation episodes (whole, truncated), an import source with huge
    spline coefficients."""
    import numpy as np

    from pathrl.dataset.synthetic import write_synthetic
    from pathrl.storage import save_checkpoint
    from pathrl.viz.synthetic import write_synthetic_episodes

    write_synthetic(fix / "tiny")
    (fix / "afile").write_text("a file where a directory or a new file is meant\n")
    (fix / "adir").mkdir()
    _model_copy(fix / "nosum", None)
    _model_copy(fix / "nogap", {"experiment": "iiwa7_random", "iterations": 600})
    (fix / "evalout" / "episodes.mcap").mkdir(parents=True)
    (fix / "exportout" / "actor.onnx").mkdir(parents=True)
    (fix / "listrun").mkdir()
    (fix / "listrun" / "config.yaml").write_text("- a\n- b\n")
    save_checkpoint({"iter": 0}, fix / "listrun" / "model_0.pt")
    (fix / "ep").mkdir()
    write_synthetic_episodes(fix / "ep" / "episodes.mcap", "iiwa7", episodes=3, steps=10, seed=1)
    (fix / "ep" / "episodes_worst2.rrd").mkdir()
    (fix / "trunc").mkdir()
    data = (fix / "ep" / "episodes.mcap").read_bytes()
    (fix / "trunc" / "episodes.mcap").write_bytes(data[:300])  # cut inside the first chunk
    rng = np.random.default_rng(0)
    (fix / "kie_huge" / "test").mkdir(parents=True)
    for i in range(2):
        knots = np.cumsum(rng.normal(scale=0.15, size=(8, 7)), axis=0)
        (fix / "kie_huge" / "test" / f"episode_{i}.json").write_text(_episode_json(knots, 1e9 if i else 1.0))


# ---------------------------------------------------------------------------------------------------------------
# running


#: Directories a snapshot skips: Python's bytecode, and the dataset loader's cache of knot tables (``.cache``, written
#: by any reader of a dataset: under ``make test``'s two workers another test may fill it meanwhile).
_SKIPPED = ("__pycache__", ".cache")


def _snapshot(roots: Sequence[Path]) -> dict[str, tuple[bool, int, int]]:
    """Every file and directory under `roots` (:data:`_SKIPPED` excepted): (is a dir, size, mtime ns).

    A directory counts by its existence only: its size and mtime change whenever an entry is added or removed, a
    skipped one included (another worker's first ``.cache``), and the entries themselves are in the snapshot.
    """
    out = {}
    for root in roots:
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames[:] = [d for d in dirnames if d not in _SKIPPED]
            for name in dirnames:
                out[os.path.join(dirpath, name)] = (True, 0, 0)
            for name in filenames:
                p = os.path.join(dirpath, name)
                st = os.lstat(p)
                out[p] = (False, st.st_size, st.st_mtime_ns)
    return out


def _tool_main(script: str) -> Callable[[list[str]], int]:
    """``main`` of a tools/ script (tools/ on the path, as for a script run from the checkout)."""
    if str(ROOT / "tools") not in sys.path:
        sys.path.insert(0, str(ROOT / "tools"))
    return importlib.import_module(Path(script).stem).main


def _train_precheck(argv: list[str]) -> int:
    """``pathrl-train``'s main with Hydra's app replaced by a stub: a case that gets past the pre-check exits 0."""
    from pathrl.cli import train

    real, saved = train._app, sys.argv
    train._app = lambda: None
    sys.argv = ["pathrl-train", *argv]
    try:
        train.main()
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else 1
    finally:
        train._app, sys.argv = real, saved
    return 0


def _entry(program: str) -> Callable[[list[str]], int]:
    """The in-process entry point of `program`."""
    if program == TRAIN:
        return _train_precheck
    if program.startswith("tools/"):
        return _tool_main(program)
    module = {EVAL: "evaluate", EXPORT: "export", TOPPRA: "toppra", DATASET: "dataset", VIEW: "view",
              IND: "industrial", ROBOT: "robot"}[program]
    return importlib.import_module(f"pathrl.cli.{module}").main


def _in_process(program: str, argv: list[str]) -> tuple[int | None, str, bool]:
    """(exit code or None, stderr with the warnings raised, whether an exception escaped) of one call."""
    err = io.StringIO()
    escaped = False
    with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stderr(err), \
            contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("always")
        try:
            code = _entry(program)(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException as exc:  # noqa: BLE001 - the outcome reports it
            code, escaped = None, True
            err.write(f"Traceback (most recent call last):\n{type(exc).__name__}: {exc}\n")
    text = err.getvalue() + "".join(f"{w.category.__name__}: {w.message}\n" for w in caught)
    return code, text, escaped


def _subprocess(program: str, argv: list[str], work: Path) -> tuple[int, str]:
    """(exit code, stderr) of `program` run in `work`."""
    cmd = [sys.executable, str(ROOT / program)] if program.startswith("tools/") else [str(BIN / program)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    r = subprocess.run([*cmd, *argv], cwd=work, env=env, capture_output=True, text=True, timeout=300)
    return r.returncode, r.stderr


def run_case(case: Case, fix: Path, work: Path) -> Outcome:
    """Run `case` with working directory `work` and inputs in `fix`; compare what is on disk before and after."""
    argv = [a.format(fix=fix, root=ROOT) for a in case.args]
    roots = [work, fix, ROOT / "models", ROOT / "datasets"]
    before = _snapshot(roots)
    t0 = time.perf_counter()
    if case.subprocess:
        code, text = _subprocess(case.program, argv, work)
        escaped = False
    else:
        cwd = Path.cwd()
        os.chdir(work)
        try:
            code, text, escaped = _in_process(case.program, argv)
        finally:
            os.chdir(cwd)
    seconds = time.perf_counter() - t0
    after = _snapshot(roots)
    left = sorted(p for p, v in after.items() if before.get(p) != v)
    lines = [ln for ln in text.strip().splitlines() if ln.strip() and not ln.startswith("pybullet build time")]
    expect = case.expect.format(fix=fix, root=ROOT)
    return Outcome(case, expect, code, lines, escaped or "Traceback" in text, left, seconds)


@contextlib.contextmanager
def fuzz_dirs():
    """(inputs dir, working dir) in a temp directory, the inputs made (:func:`make_inputs`), removed at the end."""
    with tempfile.TemporaryDirectory(prefix="pathrl-fuzz-") as tmp:
        fix, work = Path(tmp) / "in", Path(tmp) / "work"
        fix.mkdir()
        work.mkdir()
        make_inputs(fix)
        yield fix, work


def markdown(outcomes: Sequence[Outcome], fix: Path) -> str:
    """The fuzz table: case, program, exit code, stderr lines, traceback, left behind, the line (paths shortened)."""
    rows = ["| case | program | exit | stderr lines | traceback | left behind | stderr |",
            "|---|---|---|---|---|---|---|"]
    for o in outcomes:
        line = (o.lines[0] if o.lines else "").replace(str(fix), "IN").replace(str(ROOT), "ROOT").replace("|", "\\|")
        rows.append(f"| {o.case.name} | {o.case.program}{' (process)' if o.case.subprocess else ''} | {o.code} | "
                    f"{len(o.lines)} | {'yes' if o.traceback else 'no'} | {len(o.leftovers) or 'nothing'} | "
                    f"`{line}` |")
    ok = sum(o.ok for o in outcomes)
    return "\n".join(rows) + f"\n\n{ok}/{len(outcomes)} cases pass (exit 2, one line, no traceback, nothing left)."


def main(argv: list[str] | None = None) -> int:
    """Run the cases (``--only PREFIX``: those whose name starts with it), print the table; exit 1 if one fails."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--only", action="append", default=None, help="run the cases whose name starts with this")
    args = ap.parse_args(argv)
    cases = [c for c in CASES if not args.only or any(c.name.startswith(p) for p in args.only)]
    t0 = time.perf_counter()
    with fuzz_dirs() as (fix, work):
        outcomes = [run_case(c, fix, work) for c in cases]
        print(markdown(outcomes, fix))
    print(f"\n{len(cases)} cases in {time.perf_counter() - t0:.0f} s")
    for o in outcomes:
        if not o.ok:
            print(f"FAILED {o.case.name}: exit {o.code}, {o.lines[-3:]}, left {o.leftovers[:3]}", file=sys.stderr)
    return 0 if all(o.ok for o in outcomes) else 1


if __name__ == "__main__":
    raise SystemExit(main())
