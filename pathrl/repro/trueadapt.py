"""The TrueAdapt paper's Table I (online adaptation of reference trajectories, ball on plate) as data and rendering.

Each row is a setting of the paper; ``AdaptEval`` says which shipped policy (or the reference without adaptation, or
a model-based controller) fills our cells, on which split and ball. Every step goes through the TrueAdapt family's
registry (:mod:`pathrl.families.trueadapt`): an evaluation is ``pathrl-eval`` of a model directory (the reference's:
``models/trueadapt/iiwa7_trueadapt_<task>_reference``) into ``results/raw/<id>/metrics.json``; the 10^5-trajectory limit
validation (Sec. VI-D) is its ``validate`` step into ``results/raw/trueadapt_validation.json``, the time per decision
its ``timing`` step into ``results/raw/trueadapt_realtime.json`` (both run by :mod:`pathrl.cli.family_step`). The
paper's values are ``pathrl/config/paper/trueadapt.yaml`` (:mod:`pathrl.config.paper`). Rendering is a pure function
of those results."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from pathrl.config.paper import load as load_paper
from pathrl.models import model_path
from pathrl.repro.tables import training_record

__all__ = [
    "AdaptEval", "AdaptRow", "COLUMNS", "EPISODES", "EVAL_ENVS", "FAMILY_STEP", "REALTIME_ID", "ROWS", "TRAIN_MISSING",
    "VALIDATION_ID", "VALIDATION_RUN", "collect", "eval_command", "evaluations", "latex", "markdown", "method", "names",
    "ours", "paper", "realtime_command", "row_values", "seed_results", "seeds_markdown", "unavailable",
    "validation_command",
]

ADAPT_TABLE = "trueadapt_table_I"
ROBOT = "iiwa7"
#: Our metric columns (the paper's Table I), and the raw result's key and scale for each.
COLUMNS = ("success_pct", "fraction_pct", "error_distance_cm", "acc_pct", "jerk_pct")
RAW = {"success_pct": "success", "fraction_pct": "fraction", "error_distance_cm": "offset", "acc_pct": "acc",
       "jerk_pct": "jerk"}
HEADERS = ("success rate (%)", "trajectory fraction (%)", "error distance (cm)", "mean norm. \\|acc\\| (%)",
           "mean norm. \\|jerk\\| (%)")
VALIDATION_ID = "trueadapt_validation"
VALIDATION_STEPS = 100  # decision steps (5 s) per validation trajectory
REALTIME_ID = "trueadapt_realtime"
#: The policy and test split timed per decision (the on-plate row's).
REALTIME_MODEL, REALTIME_DATA = "iiwa7_trueadapt_on_plate_distill_full", "trueadapt_on_plate"
#: Evaluated trajectories: the committed test split's 1000 (the first 1000 of the train split for that row).
EPISODES = 1000
#: Envs an evaluation runs at a time.
EVAL_ENVS = 250
#: The run directory whose robot (iiwa7) the limit validation checks.
VALIDATION_RUN = f"{ROBOT}_trueadapt_on_plate_reference"
#: What runs a family's registry step that returns a result (``python -m``; :mod:`pathrl.cli.family_step`).
FAMILY_STEP = "pathrl.cli.family_step"
TRAIN_MISSING = ("not available: needs the uncommitted train split data/iiwa7/trueadapt_on_plate "
                 "(`pathrl-dataset generate robot=iiwa7 dataset=trueadapt_on_plate`)")


@dataclass(frozen=True)
class AdaptEval:
    """`models/trueadapt/<model>` (None: the reference without adaptation) on trajectories 0..EPISODES-1 of a split of
    ``trueadapt_<task>``, deterministic, seed 0."""

    task: str  # on_plate | in_place
    model: str | None = None
    split: str = "test"  # test: the committed split (datasets/); train: data/ (gitignored)
    open_loop: bool = False  # the ball measurement frozen at its first value
    backend: str = "pybullet"  # ball simulation: pybullet | analytic

    @property
    def name(self) -> str:
        """The name ``--only`` selects it by (the model, or ``iiwa7_trueadapt_<task>_reference``)."""
        return self.model or f"{ROBOT}_trueadapt_{self.task}_reference"

    @property
    def run(self) -> str:
        """Its name under ``models/trueadapt/``: the model's, or for the reference without adaptation the
        controller ``reference`` on the task's experiment config (``iiwa7_trueadapt_<task>_reference``)."""
        return self.name

    @property
    def id(self) -> str:
        """Directory under results/raw/."""
        base = self.name if self.split == "test" else f"{self.name}_{self.split}_split"
        base = f"{base}_in_pybullet" if self.backend == "pybullet" else base
        return f"{base}_open_loop" if self.open_loop else base

    @property
    def dataset(self) -> str:
        """The dataset name, ``trueadapt_<task>``."""
        return f"trueadapt_{self.task}"


@dataclass(frozen=True)
class AdaptRow:
    """A row of the TrueAdapt table: key, the paper's setting, what fills our cells and its evaluation (None: nothing
    shipped, a dash)."""

    key: str  # row key in the paper's table (pathrl/config/paper/trueadapt.yaml), or ours
    setting: str  # the paper's setting
    ours: str  # what fills our cells
    evaluation: AdaptEval | None = None  # None: nothing shipped for it (a dash)
    in_paper: bool = True
    paper_row: str | None = None  # a row of ours not in the paper shown beside this paper row's values

    @property
    def paper_key(self) -> str:
        """The key of the paper's values shown beside ours."""
        return self.paper_row or self.key


DISTILL = "iiwa7_trueadapt_on_plate_distill_full"
DISTILL_IN_PLACE = "iiwa7_trueadapt_in_place_distill_f10_decay"
PPO = "iiwa7_trueadapt_on_plate_ppo"
PPO_IN_PLACE = "iiwa7_trueadapt_in_place_ppo"
SCRATCH = "iiwa7_trueadapt_on_plate_ppo_scratch"
SCRATCH_IN_PLACE = "iiwa7_trueadapt_in_place_ppo_scratch"
_SCRATCH = ("**PPO from scratch on the paper's reward and state** (the paper's protocol; asymmetric critic, noise "
            "floor)")
_PPO = "distilled policy + PPO on the paper's reward"
_PPO_IN_PLACE = "distilled policy with the paper's state (one following position) + PPO on the paper's reward"
_STUDENT = "distilled policy"
_STUDENT_F10 = "distilled policy, ten following positions in its state (the paper's: one)"


def _ablation_row(key: str, part: str, variant: str, left_out: str) -> AdaptRow:
    """The on-plate row "state without <part>": the on-plate student's recipe (DISTILL) without `left_out` in its
    state, ``models/trueadapt/iiwa7_trueadapt_on_plate_distill_<variant>``."""
    return AdaptRow(f"on_plate/{key}", f"on plate: state without {part}", f"{_STUDENT} without {left_out} in its state",
                    AdaptEval("on_plate", f"iiwa7_trueadapt_on_plate_distill_{variant}"))


def _scratch_row(key: str, setting: str, variant: str) -> AdaptRow:
    """The on-plate ablation `key` (`setting`) trained the paper's way:
    ``models/trueadapt/iiwa7_trueadapt_on_plate_ppo_scratch_<variant>``, the from-scratch recipe of SCRATCH so
    changed."""
    return AdaptRow(f"on_plate/{key}_scratch", f"on plate: {setting}", f"**PPO from scratch**, {setting}",
                    AdaptEval("on_plate", f"{SCRATCH}_{variant}"),
                    in_paper=False, paper_row=f"on_plate/{key}")


_OPEN_LOOP_SCRATCH = "**PPO from scratch**, trained and evaluated with the ball measurement frozen"
_TRAY = "**tray controller: privileged information, not in the paper**"

ROWS: tuple[AdaptRow, ...] = (
    AdaptRow("on_plate/reference", "on plate: reference trajectories (no adaptations)", "the reference replayed",
             AdaptEval("on_plate")),
    AdaptRow("on_plate/test_set", "on plate: TrueAdapt, test set", _STUDENT, AdaptEval("on_plate", DISTILL)),
    AdaptRow("on_plate/test_set_ppo", "on plate: TrueAdapt, test set", _PPO, AdaptEval("on_plate", PPO),
             in_paper=False, paper_row="on_plate/test_set"),
    AdaptRow("on_plate/test_set_scratch", "on plate: TrueAdapt, test set", _SCRATCH, AdaptEval("on_plate", SCRATCH),
             in_paper=False, paper_row="on_plate/test_set"),
    AdaptRow("on_plate/training_set", "on plate: TrueAdapt, training set", _STUDENT + ", first 1000 training "
             "trajectories (data/)", AdaptEval("on_plate", DISTILL, split="train")),
    AdaptRow("on_plate/training_set_ppo", "on plate: TrueAdapt, training set", _PPO + ", first 1000 training "
             "trajectories (data/)", AdaptEval("on_plate", PPO, split="train"), in_paper=False,
             paper_row="on_plate/training_set"),
    AdaptRow("on_plate/open_loop_evaluation", "on plate: open loop, evaluation only",
             _STUDENT + ", ball measurement frozen", AdaptEval("on_plate", DISTILL, open_loop=True)),
    AdaptRow("on_plate/open_loop_evaluation_ppo", "on plate: open loop, evaluation only",
             _PPO + ", ball measurement frozen", AdaptEval("on_plate", PPO, open_loop=True), in_paper=False,
             paper_row="on_plate/open_loop_evaluation"),
    AdaptRow("on_plate/open_loop_evaluation_scratch", "on plate: open loop, evaluation only",
             _SCRATCH + ", ball measurement frozen", AdaptEval("on_plate", SCRATCH, open_loop=True), in_paper=False,
             paper_row="on_plate/open_loop_evaluation"),
    AdaptRow("on_plate/open_loop_training", "on plate: open loop, training and evaluation",
             _STUDENT + " trained with the ball measurement frozen (teacher too), evaluated so",
             AdaptEval("on_plate", "iiwa7_trueadapt_on_plate_distill_open_loop", open_loop=True)),
    AdaptRow("on_plate/open_loop_training_scratch", "on plate: open loop, training and evaluation",
             _OPEN_LOOP_SCRATCH, AdaptEval("on_plate", f"{SCRATCH}_open_loop", open_loop=True), in_paper=False,
             paper_row="on_plate/open_loop_training"),
    _ablation_row("no_current_position", "current position", "no_position", "the commanded position"),
    _scratch_row("no_current_position", "state without current position", "no_position"),
    _ablation_row("no_current_velocity", "current velocity", "no_velocity", "the commanded velocity"),
    _scratch_row("no_current_velocity", "state without current velocity", "no_velocity"),
    _ablation_row("no_current_acceleration", "current acceleration", "no_acceleration", "the commanded acceleration"),
    _scratch_row("no_current_acceleration", "state without current acceleration", "no_acceleration"),
    _ablation_row("no_following_positions", "following positions", "no_following", "the next reference position"),
    _scratch_row("no_following_positions", "state without following positions", "no_following"),
    AdaptRow("on_plate/ten_following_positions", "on plate: state with ten following positions",
             _STUDENT + " with the next ten reference positions in its state",
             AdaptEval("on_plate", "iiwa7_trueadapt_on_plate_distill_f10")),
    _scratch_row("ten_following_positions", "state with ten following positions", "f10"),
    AdaptRow("on_plate/no_jerk_penalty", "on plate: no jerk penalty", _PPO + " without the jerk penalty",
             AdaptEval("on_plate", PPO + "_no_jerk")),
    _scratch_row("no_jerk_penalty", "no jerk penalty", "no_jerk_penalty"),
    AdaptRow("on_plate/no_acceleration_penalty", "on plate: no acceleration penalty",
             _PPO + " without the acceleration penalty", AdaptEval("on_plate", PPO + "_no_acceleration")),
    _scratch_row("no_acceleration_penalty", "no acceleration penalty", "no_acc_penalty"),
    AdaptRow("on_plate/tray_controller", "on plate: model-based tray controller", _TRAY,
             AdaptEval("on_plate", "iiwa7_trueadapt_on_plate_tray_controller"), in_paper=False),
    AdaptRow("in_place/reference", "in place: reference trajectories (no adaptations)", "the reference replayed",
             AdaptEval("in_place")),
    AdaptRow("in_place/test_set", "in place: TrueAdapt, test set", _STUDENT_F10,
             AdaptEval("in_place", DISTILL_IN_PLACE)),
    AdaptRow("in_place/test_set_ppo", "in place: TrueAdapt, test set", _PPO_IN_PLACE,
             AdaptEval("in_place", PPO_IN_PLACE), in_paper=False, paper_row="in_place/test_set"),
    AdaptRow("in_place/test_set_scratch", "in place: TrueAdapt, test set", _SCRATCH,
             AdaptEval("in_place", SCRATCH_IN_PLACE), in_paper=False, paper_row="in_place/test_set"),
    AdaptRow("in_place/real_robot", "in place: TrueAdapt, real robot", "no real robot"),
    AdaptRow("in_place/open_loop_evaluation", "in place: open loop, evaluation only",
             _STUDENT_F10 + ", ball measurement frozen", AdaptEval("in_place", DISTILL_IN_PLACE, open_loop=True)),
    AdaptRow("in_place/open_loop_evaluation_ppo", "in place: open loop, evaluation only",
             _PPO_IN_PLACE + ", ball measurement frozen", AdaptEval("in_place", PPO_IN_PLACE, open_loop=True),
             in_paper=False, paper_row="in_place/open_loop_evaluation"),
    AdaptRow("in_place/open_loop_evaluation_scratch", "in place: open loop, evaluation only",
             _SCRATCH + ", ball measurement frozen", AdaptEval("in_place", SCRATCH_IN_PLACE, open_loop=True),
             in_paper=False, paper_row="in_place/open_loop_evaluation"),
    AdaptRow("in_place/open_loop_training", "in place: open loop, training and evaluation",
             _STUDENT_F10 + " trained with the ball measurement frozen (teacher too), evaluated so",
             AdaptEval("in_place", "iiwa7_trueadapt_in_place_distill_open_loop", open_loop=True)),
    AdaptRow("in_place/open_loop_training_scratch", "in place: open loop, training and evaluation",
             _OPEN_LOOP_SCRATCH, AdaptEval("in_place", f"{SCRATCH_IN_PLACE}_open_loop", open_loop=True),
             in_paper=False, paper_row="in_place/open_loop_training"),
    AdaptRow("in_place/tray_controller", "in place: model-based tray controller", _TRAY,
             AdaptEval("in_place", "iiwa7_trueadapt_in_place_tray_controller"), in_paper=False),
)


def evaluations(only: set[str] | None = None) -> list[AdaptEval]:
    """Distinct evaluations of the table in row order (``only``: those whose ``name`` it holds)."""
    evs = (r.evaluation for r in ROWS if r.evaluation is not None)
    return list(dict.fromkeys(e for e in evs if only is None or e.name in only))


def names() -> set[str]:
    """Every name ``--only`` accepts for this table (evaluations and the validation)."""
    return {e.name for e in evaluations()} | {VALIDATION_ID}


@cache
def paper() -> dict[str, Any]:
    """The paper's Table I (``pathrl/config/paper/trueadapt.yaml``): {"columns": [...], "rows": {key: [...]}}."""
    return load_paper("trueadapt").table(ADAPT_TABLE).as_dict()


def _rel(p: Path, root: Path) -> str:
    """`p` relative to `root` when inside it (commands run in `root`), else as given."""
    return str(p.relative_to(root)) if p.is_relative_to(root) else str(p)


def eval_command(e: AdaptEval, root: Path, raw: Path, episodes: int, reuse: bool = False) -> list[str] | None:
    """The ``pathrl-eval`` command (run in `root`; the TrueAdapt family's ``evaluate``) of `e`'s model directory
    into `raw`/<id>/metrics.json, or None when it is skipped: its model is not shipped, the train split it needs is
    not on this machine, or (`reuse`) its result exists. Test splits come from ``datasets/`` (committed), the train
    split from ``data/``; 250 envs at a time, one PyBullet worker process (evaluations run side by side)."""
    out = raw / e.id
    data = root / ("datasets" if e.split == "test" else "data")
    if unavailable(e, root / "models", data) is not None or (reuse and (out / "metrics.json").is_file()):
        return None
    return ["pathrl-eval", f"run_dir={_rel(model_path(e.run, root / 'models'), root)}",
            f"dataset.path={_rel(data / ROBOT / e.dataset, root)}", f"split={e.split}", f"episodes={episodes}",
            "seed=0", f"backend={e.backend}", "workers=1", f"num_envs={EVAL_ENVS}", f"out={_rel(out, root)}",
            *(["open_loop=true"] if e.open_loop else [])]


def validation_command(root: Path, raw: Path, trajectories: int, reuse: bool = False) -> list[str] | None:
    """The command (run in `root`; ``python``: the project's) of the Sec. VI-D limit validation into
    `raw`/trueadapt_validation.json: the TrueAdapt family's ``validate`` step of the iiwa7 (:data:`VALIDATION_RUN`'s
    robot), `trajectories` trajectories of :data:`VALIDATION_STEPS` decision steps per mode; None (`reuse` and the
    result exists)."""
    out = raw / f"{VALIDATION_ID}.json"
    if reuse and out.is_file():
        return None
    run = _rel(model_path(VALIDATION_RUN, root / "models"), root)
    return ["python", "-m", FAMILY_STEP, "trueadapt", "validate", run, _rel(out, root), f"num_envs={trajectories}",
            f"episodes={VALIDATION_STEPS}", "seed=0"]


def realtime_command(root: Path, raw: Path, models: Path, data: Path, decisions: int,
                     reuse: bool = False) -> list[str] | None:
    """The command (run in `root`) of the time per decision into `raw`/trueadapt_realtime.json: the TrueAdapt
    family's ``timing`` step of :data:`REALTIME_MODEL` on its test split, `decisions` decisions; None (`reuse` and
    the result exists, or the timed model is not shipped)."""
    out = raw / f"{REALTIME_ID}.json"
    if (reuse and out.is_file()) or not (model_path(REALTIME_MODEL, models) / "config.yaml").is_file():
        return None
    return ["python", "-m", FAMILY_STEP, "trueadapt", "timing", _rel(model_path(REALTIME_MODEL, models), root),
            _rel(out, root),
            f"dataset_path={_rel(data / ROBOT / REALTIME_DATA, root)}", f"episodes={decisions}"]


def unavailable(e: AdaptEval, models: Path, data: Path) -> str | None:
    """Why `e` is not evaluated here (its model is not shipped, or it needs the uncommitted train split and
    `data` lacks it), or None. A missing committed test split is no reason: the evaluation fails loudly."""
    if not (model_path(e.run, models) / "config.yaml").is_file():
        return f"{model_path(e.run, models)} not shipped"
    if e.split == "train" and not (data / ROBOT / e.dataset / "train.npz").is_file():
        return TRAIN_MISSING
    return None


_SEED_FILE = re.compile(r"(?P<experiment>.+)_seed(?P<seed>\d+)_pybullet_metrics\.json")


def seed_results(folder: Path) -> dict[str, dict[int, dict[str, Any]]]:
    """{experiment: {seed: metrics}} of the committed PyBullet evaluations of the from-scratch runs in `folder`
    (``<experiment>_seed<S>_pybullet_metrics.json``, written by ``tools/lab/trueadapt_scratch_queue.sh``)."""
    out: dict[str, dict[int, dict[str, Any]]] = {}
    for p in sorted(folder.glob("*_pybullet_metrics.json")) if folder.is_dir() else []:
        if (m := _SEED_FILE.fullmatch(p.name)) is not None:
            out.setdefault(m["experiment"], {})[int(m["seed"])] = json.loads(p.read_text())
    return out


def collect(raw: Path, models: Path, seeds: Path | None = None) -> dict[str, Any]:
    """{"trueadapt": {id: metrics.json}, "trueadapt_validation" and "trueadapt_realtime": their JSON or None,
    "trueadapt_training": {model: summary.json}, "trueadapt_seeds": :func:`seed_results` of `seeds`} of the results
    in `raw` (a result of a model no longer shipped is left out)."""
    out: dict[str, Any] = {"trueadapt": {}, "trueadapt_validation": None, "trueadapt_realtime": None,
                           "trueadapt_training": {}, "trueadapt_seeds": seed_results(seeds) if seeds else {}}
    for e in evaluations():
        p = raw / e.id / "metrics.json"
        if p.is_file() and (e.model is None or model_path(e.model, models).is_dir()):
            out["trueadapt"][e.id] = json.loads(p.read_text())
        record = training_record(model_path(e.model, models)) if e.model else None
        if record is not None:
            out["trueadapt_training"][e.model] = record
    for key in (VALIDATION_ID, REALTIME_ID):
        if (raw / f"{key}.json").is_file():
            out[key] = json.loads((raw / f"{key}.json").read_text())
    return out


def _fmt(x: float | None, nd: int = 1) -> str:
    return "–" if x is None else f"{x:.{nd}f}"


def ours(metrics: dict[str, Any] | None, column: str) -> float | None:
    """Our value of `column` (percent or cm) from a raw result."""
    if metrics is None or metrics.get(RAW[column]) is None:
        return None
    return 100.0 * float(metrics[RAW[column]])


def _cell(value: float | None, paper_value: float | None, task: str, column: str) -> str:
    if value is None:
        return "–" if paper_value is None else f"– / {_fmt(paper_value)}"
    if column == "error_distance_cm" and task == "on_plate":  # not the task's metric: ours in brackets
        return f"({_fmt(value)})"
    return f"**{_fmt(value)}**" if paper_value is None else f"**{_fmt(value)}** / {_fmt(paper_value)}"


def row_values(results: dict[str, Any], row: AdaptRow) -> tuple[dict[str, Any] | None, dict[str, float | None]]:
    """(raw result or None, the paper's values by column) of a row."""
    p = paper()
    pv = dict(zip(p["columns"], p["rows"].get(row.paper_key, [None] * len(p["columns"])), strict=True))
    m = None if row.evaluation is None else results.get("trueadapt", {}).get(row.evaluation.id)
    return m, pv


def _validation_line(v: list[dict[str, Any]] | None) -> str:
    if not v:
        return "Limit validation (Sec. VI-D): not run."
    mode = {"random": "random accelerations", "max": "the maximum acceleration every step"}
    parts = [f"{mode.get(r['mode'], r['mode'])}: {r['trajectories']} trajectories x {r['steps']} steps, "
             f"**{r['violations']['total']} violations** in {r['setpoints_checked']:.2e} (setpoint, joint) pairs "
             f"({r['seconds']:.0f} s)" for r in v]
    return ("Limit validation like the paper's Sec. VI-D (`tools/trueadapt_validation.py --steps "
            f"{VALIDATION_STEPS}`; accelerations drawn from the valid range, or its maximum, every 50 ms step, "
            "checked at 240 Hz against position, velocity, acceleration and jerk limits; one thread): "
            + "; ".join(parts) + ".")


def _realtime_line(r: dict[str, Any] | None) -> str:
    if not r:
        return "Time per decision: not measured."
    published = load_paper("trueadapt")
    paper_ms, paper_cpu = published.value("valid_range_ms_max"), published.value("valid_range_cpu")
    return (f"Time per decision (`python -m pathrl.eval.trueadapt_realtime`; `{r['model']}`, one env, one thread, "
            f"CPU time of the policy, the clipping into the valid range, the setpoints, the valid range and the "
            f"observation of the next decision; {r['decisions']} decisions, limits {r['limits']}): "
            f"**{r['decision_ms_mean']:.2f} ms** mean, {r['decision_ms_max']:.2f} ms max "
            f"({r['max_pct_of_cycle']:.1f} % of the {r['cycle_ms']:.0f} ms cycle); the valid range alone at most "
            f"**{r['valid_range_ms_max']:.2f} ms** (paper: at most {paper_ms} ms on an {paper_cpu}).")


CAPTION = (
    "Each cell: **ours** / paper. The ball is simulated in PyBullet for every row of ours (column *ball*; the "
    "scene draws the ball's radius, mass and friction, 2 mm sensor noise), on the 1000 trajectories of the committed "
    "test split (`datasets/iiwa7/trueadapt_<task>`; the paper: 10 000), deterministic actions, seed 0 "
    "(`tools/trueadapt_eval.py`). *PPO from scratch* (`models/trueadapt/iiwa7_trueadapt_on_plate_ppo_scratch`): the "
    "paper's "
    "protocol, no teacher and no warm start: PPO on the paper's reward and state, 500 iterations of 4096 envs x 16 "
    "steps (32.8 M steps, the paper's 32 M), analytic ball in training; two choices of ours: the critic also sees the "
    "time left and the true ball state (the policy does not), and the action noise is held at or above 0.05 "
    "(without that floor PPO shrank it to 0.01 and learnt nothing in the same budget); in place "
    "(`models/trueadapt/iiwa7_trueadapt_in_place_ppo_scratch`) the same recipe, 1300 iterations (85 M steps; the "
    "paper's "
    "220 M). Error distance: mean "
    "distance of the ball from its start, the in-place metric; "
    "on plate ours is shown in brackets. Acceleration and jerk: mean normalised |a| and |jerk| over joints and "
    "steps. Limit violations: commanded 240 Hz setpoints outside the position, velocity, acceleration or jerk "
    "limits (checked, not assumed). *Distilled policy*: `models/trueadapt/iiwa7_trueadapt_on_plate_distill_full`, a "
    "network "
    "with the paper's state taught by the tray controller (DAgger, a falling learning rate, its last checkpoint), not "
    "trained with PPO as the paper's; in place "
    "`models/trueadapt/iiwa7_trueadapt_in_place_distill_f10_decay`, the same with ten following positions in the "
    "state (the "
    "paper's ablation state) and a falling learning rate, its last checkpoint. *Distilled policy + PPO* "
    "(`models/trueadapt/iiwa7_trueadapt_on_plate_ppo`): the on-plate distilled policy trained on with PPO on the "
    "paper's "
    "reward, 250 iterations of 2048 envs x 16 steps (8.2 M steps), an asymmetric critic that also sees the time "
    "left and the true ball state, learning alone for the first 50; the penalty ablations are this run with one "
    "penalty's weight 0; in place (`models/trueadapt/iiwa7_trueadapt_in_place_ppo`) the same recipe from the "
    "one-position "
    "student (`models/trueadapt/iiwa7_trueadapt_in_place_distill_decay`), 600 iterations (19.7 M steps). *Tray "
    "controller*: `models/trueadapt/iiwa7_trueadapt_<task>_tray_controller` (`pathrl/baselines/trueadapt_tray.py`), no "
    "learning; it reads privileged information a policy does not get (the whole reference with its velocities and "
    "accelerations, the plate kinematics, its own filter state), so it is a feasibility bound, not a result "
    "comparable with the paper's. *State ablations* (`models/trueadapt/iiwa7_trueadapt_on_plate_distill_<variant>`): "
    "the "
    "on-plate student's recipe with one part of its state left out; the teacher is the same controller, so these rows "
    "measure what the network needs in order to copy it, not what PPO needs to learn the task. *From-scratch "
    "ablations* (`models/trueadapt/iiwa7_trueadapt_on_plate_ppo_scratch_<variant>`): the paper's protocol for the same "
    "question, the from-scratch recipe and budget with one part of the state or one penalty removed, ten following "
    "positions, or the ball frozen in training too (open loop), seed 0 (every seed below the table). *Trained by*: "
    "read from each shipped policy's config: PPO from scratch, PPO from <model> (a warm start), DAgger from "
    "<teacher>, or not trained. Rows without a trained policy of ours show a dash.")


def method(results: dict[str, Any], row: AdaptRow) -> str:
    """How the row's policy was trained (:func:`pathrl.repro.tables.training_method`, from its shipped config), or
    ``not trained (reference replayed)``; a dash without a shipped model."""
    if row.evaluation is None:
        return "–"
    if row.evaluation.model is None:
        return "not trained (reference replayed)"
    training = {**results.get("trueadapt_training", {}), **results.get("training", {})}
    return training.get(row.evaluation.model, {}).get("method", "–")


def _pct(values: list[float]) -> str:
    """Percentages of fractions, one decimal, joined by ' / '."""
    return " / ".join(f"{100 * v:.1f}" for v in values)


def seeds_markdown(seeds: dict[str, dict[int, dict[str, Any]]]) -> list[str]:
    """Every seed of every from-scratch experiment evaluated in PyBullet: success, fraction, |a|, |jerk|, violations
    per seed (seed order) and the mean success."""
    if not seeds:
        return []
    lines = ["", "PPO from scratch, every seed (the table above shows seed 0; PyBullet, the 1000 test trajectories; "
             "`results/trueadapt_from_scratch/<experiment>_seed<S>_pybullet_metrics.json`, learning curves "
             "`<experiment>_seed<S>.csv` beside them; `tools/lab/trueadapt_scratch_queue.sh`):", "",
             "| experiment | seeds | success (%) | mean success (%) | fraction (%) | \\|acc\\| (%) | \\|jerk\\| (%) | "
             "limit violations |", "|---|---|---|---|---|---|---|---|"]
    for exp, runs in seeds.items():
        ms = [runs[k] for k in sorted(runs)]
        mean = 100 * sum(m["success"] for m in ms) / len(ms)
        lines.append(f"| `{exp}` | {', '.join(map(str, sorted(runs)))} | {_pct([m['success'] for m in ms])} | "
                     f"{mean:.1f} | {_pct([m['fraction'] for m in ms])} | {_pct([m['acc'] for m in ms])} | "
                     f"{_pct([m['jerk'] for m in ms])} | {sum(int(m['limit_violations']) for m in ms)} |")
    return lines


def markdown(results: dict[str, Any]) -> tuple[list[str], list[list[str]]]:
    """The table's Markdown lines and CSV rows (table, row, metric, ours, paper)."""
    lines = ["## TrueAdapt Table I: online adaptation of reference trajectories (iiwa7, ball on plate, PyBullet)",
             "", CAPTION, "",
             "| setting | ours | trained by | " + " | ".join(HEADERS) + " | ball | episodes | limit violations |",
             "|---|---|---|" + "---|" * (len(HEADERS) + 3)]
    csv_rows: list[list[str]] = []
    for row in ROWS:
        m, pv = row_values(results, row)
        task = row.key.split("/")[0]
        what = row.ours
        if m is None and row.evaluation is not None and row.evaluation.split == "train":
            what = f"{row.ours}; {TRAIN_MISSING}"
        cells = [_cell(ours(m, c), pv[c], task, c) for c in COLUMNS]
        tail = ["–", "–", "–"] if m is None else [str(m.get("backend", "–")), str(m["episodes"]),
                                                   str(m.get("limit_violations", "–"))]
        lines.append(f"| {row.setting} | {what} | {method(results, row)} | " + " | ".join(cells + tail) + " |")
        for c in COLUMNS:
            x = ours(m, c)
            csv_rows.append([ADAPT_TABLE, row.key, c, "" if x is None else f"{x:.6g}",
                             "" if pv[c] is None else f"{pv[c]:g}"])
        if m is not None:
            csv_rows.append([ADAPT_TABLE, row.key, "limit_violations", str(m.get("limit_violations", "")), ""])
    v = results.get("trueadapt_validation")
    rt = results.get(REALTIME_ID)
    lines += seeds_markdown(results.get("trueadapt_seeds") or {})
    lines += ["", _validation_line(v), "", _realtime_line(rt)]
    if rt:
        csv_rows.append([ADAPT_TABLE, "realtime", "valid_range_ms_max", f"{rt['valid_range_ms_max']:.6g}", "0.9"])
    for r in v or []:
        csv_rows.append([ADAPT_TABLE, f"validation/{r['mode']}", "limit_violations", str(r["violations"]["total"]),
                         "0"])
    return lines, csv_rows


def latex(results: dict[str, Any]) -> list[str]:
    """The table as a booktabs tabular, cells ``ours (paper)``."""
    out = ["% TrueAdapt Table I: online adaptation of reference trajectories (ball in PyBullet)",
           r"\begin{tabular}{l" + "r" * len(COLUMNS) + "}", r"\toprule",
           "setting & " + " & ".join(c.replace("_", r"\_") for c in COLUMNS) + r" \\", r"\midrule"]
    for row in ROWS:
        m, pv = row_values(results, row)
        cells = [f"{_fmt(ours(m, c)).replace('–', '--')} ({_fmt(pv[c]).replace('–', '--')})" for c in COLUMNS]
        out.append(row.key.replace("_", r"\_") + " & " + " & ".join(cells) + r" \\")
    return [*out, r"\bottomrule", r"\end{tabular}", ""]
