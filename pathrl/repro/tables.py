"""The paper's Tables I-VII as data: which shipped policy, test split and TOPP-RA run fill each row.

An *evaluation* is one policy on one test split (``Evaluation``); a *baseline* is TOPP-RA on the same
split, knots and episode plan (``Baseline``). Several rows share them (iiwa7 random fills a row of
Tables I, II, III and VI), so each is computed once.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

#: Columns of Tables II-IV (and the deviation columns of the Pareto plot).
SHORT_COLUMNS = ("duration_s", "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm", "cart_pos_dev_final_cm")


@dataclass(frozen=True)
class Evaluation:
    """`models/<model>` evaluated on `data/<robot>/<dataset>` (test split)."""

    model: str
    robot: str
    dataset: str
    knots: str = "curvature_9"
    segments: str = "paper"  # paper (random segments) | full (whole paths)
    generalization: bool = False  # evaluated on another dataset than the one it was trained on
    task: str | None = None  # evaluated with this feedback task in PyBullet (e.g. ball_on_plate)
    episodes: int | None = None  # default: 1200 paper segments, or every path once for segments=full
    open_loop: bool = False  # the task's sensor frozen at its first value (does the policy use the feedback?)
    second_test_set: bool = False  # on `<dataset>_test2`: the same generator's next seed, never trained on

    @property
    def id(self) -> str:
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
    table: str  # key in paper_tables.yaml
    key: str  # row key in that table
    evaluation: Evaluation


def _e(model: str, robot: str, dataset: str, knots: str = "curvature_9", segments: str = "paper",
       generalization: bool = False, task: str | None = None, episodes: int | None = None,
       open_loop: bool = False, second_test_set: bool = False) -> Evaluation:
    return Evaluation(model, robot, dataset, knots, segments, generalization, task, episodes, open_loop,
                      second_test_set)


def _ball(model: str, open_loop: bool = False) -> Evaluation:
    """`model` on the whole ball-balancing test paths in PyBullet."""
    return _e(model, "iiwa7", "ball_balancing", "distance_5", "full", task="ball_on_plate", open_loop=open_loop)


def greedy_model(ev: Evaluation) -> str:
    """The greedy follower's model dir for a row's robot and paths (one per Table I row, whatever its policy)."""
    return f"greedy_{ev.robot}_{ev.dataset}"


IIWA_RANDOM = _e("iiwa7_random", "iiwa7", "random")
ARMAR4_RANDOM = _e("armar4_random", "armar4", "random")

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

TABLE_I_ROWS: tuple[Row, ...] = (
    # trained on from iiwa7_random with the path length weighted 6 (conf/experiment/iiwa7_random_continue.yaml);
    # Tables II-IV keep iiwa7_random, whose rows share one budget
    Row(TABLE_I, "iiwa7/random", _e("iiwa7_random_continue", "iiwa7", "random")),
    Row(TABLE_I, "iiwa7/target_point", _e("iiwa7_target_point", "iiwa7", "target_point")),
    # trained with the path length weighted 1 (conf/experiment/iiwa7_ball_balancing_length_lt.yaml); Table VII's rows
    # keep iiwa7_ball_balancing (weight 4), their warm starts
    Row(TABLE_I, "iiwa7/ball_balancing", _e("iiwa7_ball_balancing_length_lt", "iiwa7", "ball_balancing", "distance_5",
                                            "full")),
    # trained on from armar6_random at a lower path-length weight (conf/experiment/armar6_random_continue.yaml)
    Row(TABLE_I, "armar6/random", _e("armar6_random_continue", "armar6", "random")),
    Row(TABLE_I, "armar4_fixed/random", ARMAR4_RANDOM),
    # trained on from armar4_target_point at low action noise (conf/experiment/armar4_target_point_continue.yaml)
    Row(TABLE_I, "armar4_fixed/target_point", _e("armar4_target_point_continue", "armar4", "target_point")),
)

#: Table I rows without a second test split (the ball-balancing paths have none yet).
NO_SECOND_TEST_SET = frozenset({"iiwa7/ball_balancing"})

#: Tables of ours alone (no counterpart in the paper); their rows feed other tables' columns.
OURS_ONLY = frozenset({TABLE_GREEDY})

ROWS: tuple[Row, ...] = (
    *TABLE_I_ROWS,
    *(Row(TABLE_GREEDY, r.key, replace(r.evaluation, model=greedy_model(r.evaluation))) for r in TABLE_I_ROWS),
    *(Row(TABLE_I_TEST2, r.key, replace(r.evaluation, second_test_set=True)) for r in TABLE_I_ROWS
      if r.key not in NO_SECOND_TEST_SET),
    Row(TABLE_II, "length_lt_deviation", _e("iiwa7_random_length_lt_deviation", "iiwa7", "random")),
    Row(TABLE_II, "length_eq_deviation", _e("iiwa7_random_length_eq_deviation", "iiwa7", "random")),
    Row(TABLE_II, "length_gt_deviation", IIWA_RANDOM),
    Row(TABLE_III, "knots_5", _e("iiwa7_random_knots5", "iiwa7", "random", "curvature_5")),
    Row(TABLE_III, "knots_7", _e("iiwa7_random_knots7", "iiwa7", "random", "curvature_7")),
    Row(TABLE_III, "knots_9", IIWA_RANDOM),
    Row(TABLE_IV, "iiwa7", _e("iiwa7_random", "iiwa7", "target_point", generalization=True)),
    Row(TABLE_IV, "armar4_fixed", _e("armar4_random", "armar4", "target_point", generalization=True)),
    # the tracking policy with the ball riding along unobserved; the policy trained with ball feedback
    Row(TABLE_VII, "no_balancing_reward", _ball("iiwa7_ball_balancing")),
    Row(TABLE_VII, "balancing_reward", _ball("iiwa7_ball_balancing_reward")),
    # not in the paper: the same policy with the ball sensor frozen (open loop), and the model-based controller
    # (pathrl.baselines.ball_feedback, no learning) closed and open loop
    Row(TABLE_VII, "balancing_reward/open_loop", _ball("iiwa7_ball_balancing_reward", open_loop=True)),
    Row(TABLE_VII, "model_based_feedback", _ball("iiwa7_ball_tray_controller")),
    Row(TABLE_VII, "model_based_feedback/open_loop", _ball("iiwa7_ball_tray_controller", open_loop=True)),
    # the controller taught to the policy network (DAgger, pathrl.train.distill), then fine-tuned with PPO
    Row(TABLE_VII, "distilled", _ball("iiwa7_ball_balancing_distill")),
    Row(TABLE_VII, "distilled/open_loop", _ball("iiwa7_ball_balancing_distill", open_loop=True)),
    Row(TABLE_VII, "distilled_ppo", _ball("iiwa7_ball_balancing_finetune")),
    Row(TABLE_VII, "distilled_ppo/open_loop", _ball("iiwa7_ball_balancing_finetune", open_loop=True)),
    # the same with the controller on the path-dependent time law (pathrl.baselines.tray_time_law)
    Row(TABLE_VII, "model_based_feedback_path_law", _ball("iiwa7_ball_tray_law")),
    Row(TABLE_VII, "model_based_feedback_path_law/open_loop", _ball("iiwa7_ball_tray_law", open_loop=True)),
    Row(TABLE_VII, "distilled_path_law", _ball("iiwa7_ball_balancing_distill_law")),
    Row(TABLE_VII, "distilled_path_law_ppo", _ball("iiwa7_ball_balancing_finetune_law")),
    Row(TABLE_VII, "distilled_path_law_ppo/open_loop", _ball("iiwa7_ball_balancing_finetune_law", open_loop=True)),
    # PPO on a residual over the path-law controller (pathrl.policy.residual): starts as the controller
    Row(TABLE_VII, "residual_path_law_ppo", _ball("iiwa7_ball_balancing_residual")),
    Row(TABLE_VII, "residual_path_law_ppo/open_loop", _ball("iiwa7_ball_balancing_residual", open_loop=True)),
    # free-standing ARMAR-4 in PyBullet, 200 paper segments each (a PyBullet episode costs ~1 s of CPU)
    Row(TABLE_VIII, "fixed_legs/no_balancing_reward", _e("armar4_target_point", "armar4", "target_point",
                                                         task="standing", episodes=200)),
    Row(TABLE_VIII, "fixed_legs/balancing_reward", _e("armar4_target_point_balancing", "armar4", "target_point",
                                                      task="standing", episodes=200)),
    Row(TABLE_VIII, "controlled_legs/balancing_reward", _e("armar4_legs_target_point_balancing", "armar4_legs",
                                                           "target_point", task="standing", episodes=200)),
    # not in the paper: that policy's upper body with a model-based leg balance law (pathrl.baselines.balance)
    Row(TABLE_VIII, "controlled_legs/balance_controller", _e("armar4_legs_balance_controller", "armar4_legs",
                                                             "target_point", task="standing", episodes=200)),
    # the same law with a guard on the zero-moment point of the commanded next step and a 0.3 s preview
    Row(TABLE_VIII, "controlled_legs/balance_dynamic", _e("armar4_legs_balance_dynamic", "armar4_legs",
                                                          "target_point", task="standing", episodes=200)),
)


#: Tables of ours whose rows compare with a table of the paper (same row keys).
PAPER_TABLE = {TABLE_I_TEST2: TABLE_I}

#: Rows of ours that the paper does not have (shown with a dash for the paper's value).
NOT_IN_PAPER = frozenset({(TABLE_VII, "balancing_reward/open_loop"), (TABLE_VII, "model_based_feedback"),
                          (TABLE_VII, "model_based_feedback/open_loop"), (TABLE_VII, "distilled"),
                          (TABLE_VII, "distilled/open_loop"), (TABLE_VII, "distilled_ppo"),
                          (TABLE_VII, "distilled_ppo/open_loop"), (TABLE_VII, "model_based_feedback_path_law"),
                          (TABLE_VII, "model_based_feedback_path_law/open_loop"), (TABLE_VII, "distilled_path_law"),
                          (TABLE_VII, "distilled_path_law_ppo"), (TABLE_VII, "distilled_path_law_ppo/open_loop"),
                          (TABLE_VII, "residual_path_law_ppo"), (TABLE_VII, "residual_path_law_ppo/open_loop"),
                          (TABLE_VIII, "controlled_legs/balance_controller"),
                          (TABLE_VIII, "controlled_legs/balance_dynamic")})

#: Model directories that hold a model-based controller (``controller:`` in config.yaml): evaluated, not trained.
CONTROLLER_MODELS = frozenset({"iiwa7_ball_tray_controller", "iiwa7_ball_tray_law", "armar4_legs_balance_controller",
                               "armar4_legs_balance_dynamic",
                               *(greedy_model(r.evaluation) for r in TABLE_I_ROWS)})


#: Rows trained from another row's policy (conf/experiment/<model>.yaml: init_from: models/<source>).
WARM_STARTS = {"iiwa7_ball_balancing_reward": "iiwa7_ball_balancing",
               "iiwa7_ball_balancing_imu": "iiwa7_ball_balancing_reward",
               "iiwa7_ball_balancing_drive": "iiwa7_ball_balancing_reward",
               "iiwa7_ball_balancing_tcp": "iiwa7_ball_balancing_reward",
               "iiwa7_ball_balancing_finetune": "iiwa7_ball_balancing_distill",
               "iiwa7_ball_balancing_finetune_law": "iiwa7_ball_balancing_distill_law",
               "armar4_target_point_balancing": "armar4_target_point",
               "armar4_legs_target_point_balancing": "armar4_target_point",
               "iiwa7_random_continue": "iiwa7_random",
               "armar6_random_continue": "armar6_random",
               "armar4_target_point_continue": "armar4_target_point",
               "armar4_target_point_fast": "armar4_target_point_continue",
               "armar4_target_point_fast_continue": "armar4_target_point_fast",
               "iiwa7_random_path_change": "iiwa7_random_continue"}


def warm_chain(model: str) -> list[str]:
    """The models `model` is warm-started from, the first trained first (empty for a policy trained from scratch)."""
    chain: list[str] = []
    while model in WARM_STARTS:
        model = WARM_STARTS[model]
        if model in chain:
            raise ValueError(f"WARM_STARTS: a cycle through {model}")
        chain.insert(0, model)
    return chain


#: The authors' budget per policy: (million env steps, wall time in hours), from their checkpoints' training
#: metadata (iterations x train batch; Ray RLlib on a cluster node).
AUTHORS_BUDGETS = {"iiwa7_random": (195, 45.2), "iiwa7_target_point": (300, 65.3),
                   "iiwa7_ball_balancing": (150, 30.8), "iiwa7_ball_balancing_length_lt": (150, 30.8),
                   "iiwa7_ball_balancing_reward": (629, 122.5),
                   "armar6_random": (619, 238.4), "armar4_random": (137, 137.0), "armar4_target_point": (110, 93.8),
                   "armar4_target_point_balancing": (156, 176.8), "armar4_legs_target_point_balancing": (169, 229.9)}


def evaluations(rows: tuple[Row, ...] = ROWS) -> list[Evaluation]:
    """Distinct evaluations in table order."""
    return list(dict.fromkeys(r.evaluation for r in rows))


def baselines(rows: tuple[Row, ...] = ROWS) -> list[Baseline]:
    """Distinct TOPP-RA runs in table order."""
    return list(dict.fromkeys(r.evaluation.baseline for r in rows))


def table_i_row(key: str) -> Row:
    return next(r for r in ROWS if r.table == TABLE_I and r.key == key)
