"""The paper's Tables I-VIII as data: which shipped policy, test split and TOPP-RA run fill each row.

An *evaluation* is one policy on one test split (``Evaluation``); a *baseline* is TOPP-RA on the same
split, knots and episode plan (``Baseline``). Several rows share them (iiwa7 random fills a row of
Tables I, II, III and VI), so each is computed once. The rows are read from ``sweeps/<table>.yaml``
(:mod:`pathrl.repro.sweeps`, package data), the warm starts from the experiments' ``init_from``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from pathrl.config.paths import CONF_DIR
from pathrl.repro.sweeps import SWEEPS_DIR, load_tables, warm_starts

__all__ = [
    "AUTHORS_BUDGETS", "Baseline", "CONTROLLER_MODELS", "Evaluation", "NOT_IN_PAPER", "NO_SECOND_TEST_SET", "OURS_ONLY",
    "PAPER_TABLE", "PATH_CHANGE", "PATH_ROBOT", "REALTIME", "ROWS", "Row", "SHORT_COLUMNS", "SWEEPS", "TABLE_FILES",
    "TABLE_GREEDY", "TABLE_I", "TABLE_II", "TABLE_III", "TABLE_IV", "TABLE_IX", "TABLE_I_TEST2", "TABLE_PATH_CHANGE",
    "TABLE_V", "TABLE_VI", "TABLE_VII", "TABLE_VIII", "TEST2_SUFFIX", "WARM_STARTS", "baselines", "evaluations",
    "greedy_model", "select", "table_i_row", "training_method", "training_record", "warm_chain",
]

#: Columns of Tables II-IV (and the deviation columns of the Pareto plot).
SHORT_COLUMNS = ("duration_s", "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm", "cart_pos_dev_final_cm")


@dataclass(frozen=True)
class Evaluation:
    """`models/<family>/<model>` evaluated on `data/<robot>/<dataset>` (test split)."""

    model: str
    robot: str
    dataset: str
    knots: str = "curvature_9"
    segments: str = "paper"  # paper (random segments) | full (whole paths)
    generalization: bool = False  # evaluated on another dataset than the one it was trained on
    train_dataset: str | None = None  # generalization: the dataset the policy trains on (make reproduce-tables --train)
    task: str | None = None  # evaluated with this feedback task in PyBullet (e.g. ball_on_plate)
    episodes: int | None = None  # default: 1200 paper segments, or every path once for segments=full
    open_loop: bool = False  # the task's sensor frozen at its first value (does the policy use the feedback?)
    second_test_set: bool = False  # on `<dataset>_test2`: the same generator's next seed, never trained on

    @property
    def id(self) -> str:
        """Key of the evaluation's results (``results["evaluations"]``)."""
        base = f"{self.model}_on_{self.dataset}" if self.generalization else self.model
        base = f"{base}_in_pybullet" if self.task else base
        base = f"{base}{TEST2_SUFFIX}" if self.second_test_set else base
        return f"{base}_open_loop" if self.open_loop else base

    @property
    def test_dir(self) -> str:
        """Directory name of the test split under ``datasets/<data_robot>/``."""
        return f"{self.dataset}{TEST2_SUFFIX}" if self.second_test_set else self.dataset

    @property
    def data_robot(self) -> str:
        """Whose datasets the policy tracks (``datasets/<data_robot>/<dataset>``)."""
        return PATH_ROBOT.get(self.robot, self.robot)

    @property
    def baseline(self) -> Baseline:
        """The TOPP-RA baseline on the same test split and episode plan."""
        return Baseline(self.data_robot, self.test_dir, _knot_positions(self.knots), self.segments)


@dataclass(frozen=True)
class Baseline:
    """TOPP-RA on `data/<robot>/<dataset>` (test split) with the evaluation's episode plan."""

    robot: str
    dataset: str
    knots: str
    segments: str

    @property
    def id(self) -> str:
        """Key of the baseline's results (``results["baselines"]``)."""
        return f"toppra_{self.robot}_{self.dataset}_{self.segments}"


#: Suffix of a second test split: ``datasets/<robot>/<dataset>_test2`` holds 200 test paths of the same
#: generator and settings with the next seed (``pathrl-dataset generate ... dataset.seed=<seed + 1>
#: dataset.num_train=0``), never trained on or tuned for; over-fitting to the first split shows there.
TEST2_SUFFIX = "_test2"

#: Robots whose paths (path joints and their limits) are another robot's: TOPP-RA runs once for both.
PATH_ROBOT = {"armar4_legs": "armar4"}


def _knot_positions(knots: str) -> str:
    """Knot configs that differ only in how many knots the state shows share positions (and so the plan)."""
    strategy, _ = knots.rsplit("_", 1)
    return f"{strategy}_9"


@dataclass(frozen=True)
class Row:
    """A table row: the table and row key in ``pathrl/config/paper/tracking.yaml`` and the evaluation that fills it."""

    table: str  # key in pathrl/config/paper/tracking.yaml
    key: str  # row key in that table
    evaluation: Evaluation


def greedy_model(ev: Evaluation) -> str:
    """The greedy follower's model dir for a row's robot and paths (one per Table I row, whatever its policy)."""
    return f"greedy_{ev.robot}_{ev.dataset}"


TABLE_I = "table_I_tracking_no_feedback"
TABLE_I_TEST2 = "table_I_second_test_set"  # ours: Table I's policies on the second test splits
TABLE_II = "table_II_tradeoff_length_vs_deviation"
TABLE_III = "table_III_knots_in_state"
TABLE_IV = "table_IV_generalization_random_to_target_point"
TABLE_V = "table_V_features_vs_toppra"
TABLE_VI = "table_VI_toppra_timing"
TABLE_VII = "table_VII_ball_on_plate"
TABLE_VIII = "table_VIII_armar4_balance"
TABLE_IX = "table_IX_computation_time"
TABLE_PATH_CHANGE = "path_adjustments"  # ours: Table V's "path adjustments: yes", measured
TABLE_GREEDY = "greedy_follower"  # ours: the non-learned follower on the Table I segments (a Table VI column)

#: Table IX rows: (row key, robot, test split whose segments are timed).
REALTIME = (("iiwa7", "iiwa7", "iiwa7/random"), ("armar4_with_legs", "armar4_legs", "armar4/target_point"),
            ("armar6", "armar6", "armar6/random"))

#: Path-adjustment rows (pathrl.eval.path_change): (row key, shipped model, test split).
PATH_CHANGE = (("iiwa7/random", "iiwa7_random", "iiwa7/random"), ("armar6/random", "armar6_random", "armar6/random"))

#: sweeps/<name>.yaml -> the table its rows fill, in row order (the order of ``evaluations()``).
TABLE_FILES = {"table_I": TABLE_I, "greedy_follower": TABLE_GREEDY, "table_I_test2": TABLE_I_TEST2,
               "table_II": TABLE_II, "table_III": TABLE_III, "table_IV": TABLE_IV, "table_VII": TABLE_VII,
               "table_VIII": TABLE_VIII}

#: The sweeps/ files as read (rows, training sweep), by file stem.
SWEEPS = load_tables(SWEEPS_DIR, tuple(TABLE_FILES), Evaluation)

ROWS: tuple[Row, ...] = tuple(Row(TABLE_FILES[name], r.key, r.evaluation) for name, spec in SWEEPS.items()
                              for r in spec.rows)

TABLE_I_ROWS: tuple[Row, ...] = tuple(r for r in ROWS if r.table == TABLE_I)

#: Table I rows without a second test split (the ball-balancing paths have none yet).
NO_SECOND_TEST_SET = frozenset(r.key for r in TABLE_I_ROWS) - {r.key for r in ROWS if r.table == TABLE_I_TEST2}

#: Tables of ours alone (no counterpart in the paper); their rows feed other tables' columns.
OURS_ONLY = frozenset(TABLE_FILES[name] for name, spec in SWEEPS.items() if spec.ours_only)

#: Tables of ours whose rows compare with a table of the paper (same row keys).
PAPER_TABLE = {TABLE_FILES[name]: spec.paper_table for name, spec in SWEEPS.items() if spec.paper_table}

#: Rows of ours that the paper does not have (shown with a dash for the paper's value).
NOT_IN_PAPER = frozenset((TABLE_FILES[name], r.key) for name, spec in SWEEPS.items() for r in spec.rows
                         if r.not_in_paper)

#: Model directories that hold a model-based controller (``controller:`` in config.yaml): evaluated, not trained.
CONTROLLER_MODELS = frozenset(r.evaluation.model for spec in SWEEPS.values() for r in spec.rows if r.controller)

#: Rows trained from another row's policy: {model: source} from conf/experiment/<model>.yaml's
#: ``init_from: models/<family>/<source>`` (own or through its defaults list).
WARM_STARTS = warm_starts(CONF_DIR / "experiment")


def select(only: set[str] | None) -> tuple[Row, ...]:
    """The rows whose model, or whose sweeps/ file (``table_II``), `only` names (None: every row)."""
    if only is None:
        return ROWS
    files = {table: name for name, table in TABLE_FILES.items()}
    return tuple(r for r in ROWS if r.evaluation.model in only or files[r.table] in only)


def warm_chain(model: str) -> list[str]:
    """The models `model` is warm-started from, the first trained first (empty for a policy trained from scratch)."""
    chain: list[str] = []
    while model in WARM_STARTS:
        model = WARM_STARTS[model]
        if model in chain:
            raise ValueError(f"WARM_STARTS: a cycle through {model}")
        chain.insert(0, model)
    return chain


def training_method(cfg: dict[str, Any]) -> str:
    """How the policy of a run config was trained: ``PPO from scratch``, ``PPO from <model>`` for a warm start
    (``init_from``), either with ``, <term> weight curriculum`` when a reward weight moved during training,
    ``PPO residual over <controller>, from ...`` for a residual policy (it runs beside the controller),
    ``DAgger from <teacher>`` for a distilled student (``DAgger from <teacher> around <model>`` when the teacher
    wraps a shipped policy), ``not trained (<controller>)`` for a
    model-based controller's directory, ``<controller> around <model>`` for a controller that wraps a shipped
    policy."""
    controller = cfg.get("controller")
    if controller:
        name = controller.get("name", "controller")
        policy = controller.get("policy")
        return f"{name} around {Path(policy).name}" if policy else f"not trained ({name})"
    algorithm = ((cfg.get("agent") or {}).get("algorithm") or {}).get("class_name", "PPO")
    if algorithm == "Distillation":
        teacher = cfg.get("teacher") or {}
        around = f" around {Path(teacher['policy']).name}" if teacher.get("policy") else ""
        return f"DAgger from {teacher.get('name', 'a controller')}{around}"
    start = cfg.get("init_from")
    origin = f"from {Path(str(start)).name if start else 'scratch'}"
    curriculum = cfg.get("reward_curriculum") or {}
    if curriculum.get("term"):  # the reward's weights moved during training (pathrl.train.curricula)
        moved = [curriculum["term"], *(curriculum.get("also") or [])]
        origin += f", {' and '.join(moved)} weight curriculum"
    residual = (cfg.get("residual") or {}).get("controller")
    if residual:
        return f"{algorithm} residual over {residual.get('name', 'a controller')}, {origin}"
    return f"{algorithm} {origin}"


def training_record(model_dir: Path) -> dict[str, Any] | None:
    """A shipped policy's ``summary.json`` with its ``method`` (:func:`training_method` of its config.yaml); None
    if it has no summary."""
    summary, config = Path(model_dir) / "summary.json", Path(model_dir) / "config.yaml"
    if not summary.is_file():
        return None
    record = json.loads(summary.read_text())
    if config.is_file():
        record["method"] = training_method(yaml.safe_load(config.read_text()) or {})
    return record


#: The authors' budget per policy: (million env steps, wall time in hours), from their checkpoints' training
#: metadata (iterations x train batch; Ray RLlib on a cluster node).
AUTHORS_BUDGETS = {"iiwa7_random": (195, 45.2), "iiwa7_random_track_distill": (195, 45.2),
                   "iiwa7_target_point": (300, 65.3), "iiwa7_target_point_track_distill": (300, 65.3),
                   "iiwa7_ball_balancing": (150, 30.8), "iiwa7_ball_balancing_length_lt": (150, 30.8),
                   "iiwa7_ball_balancing_track_distill": (150, 30.8),
                   "iiwa7_ball_balancing_reward": (629, 122.5),
                   "iiwa7_ball_balancing_reward_scratch_length_curriculum": (629, 122.5),
                   "iiwa7_ball_balancing_reward_scratch_big_batch": (629, 122.5),
                   "iiwa7_ball_balancing_reward_scratch_deviation": (629, 122.5),
                   "armar6_random": (619, 238.4), "armar6_random_track_distill": (619, 238.4),
                   "armar4_random": (137, 137.0),
                   "armar4_random_track_distill": (137, 137.0), "armar4_target_point": (110, 93.8),
                   "armar4_target_point_track_distill": (110, 93.8),
                   "armar4_target_point_balancing": (156, 176.8), "armar4_legs_target_point_balancing": (169, 229.9)}


def evaluations(rows: tuple[Row, ...] = ROWS) -> list[Evaluation]:
    """Distinct evaluations in table order."""
    return list(dict.fromkeys(r.evaluation for r in rows))


def baselines(rows: tuple[Row, ...] = ROWS) -> list[Baseline]:
    """Distinct TOPP-RA runs in table order."""
    return list(dict.fromkeys(r.evaluation.baseline for r in rows))


def table_i_row(key: str) -> Row:
    """The Table I row with key `key` (StopIteration if none)."""
    return next(r for r in ROWS if r.table == TABLE_I and r.key == key)
