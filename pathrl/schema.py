"""Dataclass schemas of every config group. Hydra validates composed YAML against these.

The schema names the keys and their types; defaults live in ``conf/``. The ``env`` group's schema is the env's own
settings class (:class:`pathrl.envs.tracking_cfg.EnvSettings`, defaults there), also used at run time, so the schemas
sit above the env (the rest of config support, below every layer: :mod:`pathrl.config`). A resolved ``pathrl-train``
config becomes its typed object once (:func:`train_app_cfg`; the CLI: ``OmegaConf.to_object``), and goes back to the
plain dict it was composed as (:func:`config_dict`: the saved ``config.yaml``, the dict-reading env registry).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from omegaconf import MISSING, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from pathrl.config.migrate import CONFIG_VERSION
from pathrl.envs.path_change_cfg import PathChangeCfg
from pathrl.envs.tracking_cfg import EnvSettings

__all__ = [
    "BallCurriculumCfg", "CriticWarmupCfg", "DatasetAppCfg", "DatasetCfg", "EvalAppCfg", "EvalDatasetCfg",
    "ExportAppCfg", "ExportDatasetCfg", "KnotsCfg", "LrDecayCfg", "RewardCfg", "RewardCurriculumCfg", "RobotCfg",
    "StdAnnealCfg", "TaskCfg", "TcpCfg", "ToppraAppCfg", "TrainAppCfg", "WorkspaceCfg", "config_dict",
    "train_app_cfg",
]


@dataclass
class TcpCfg:
    """A tool centre point: the URDF ``link`` it is fixed to and its ``offset`` in that link's frame (m)."""

    link: str = MISSING
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])


@dataclass
class WorkspaceCfg:
    """The Cartesian workspace box of a robot: [min, max] along ``x``, ``y``, ``z`` (m, base frame)."""

    x: list[float] = MISSING
    y: list[float] = MISSING
    z: list[float] = MISSING


@dataclass
class RobotCfg:
    """A robot (``conf/robot/*.yaml``): URDF, joints, the path joints, kinematic limits (rad, rad/s, rad/s², rad/s³),
    deviation weights, TCPs and workspace."""

    name: str = MISSING
    urdf: str = MISSING
    fixed_base: bool = True
    joints: list[str] = MISSING
    path_joints: list[str] = MISSING
    position_limits: list[list[float]] = MISSING
    position_margin: float = 0.0
    velocity_limits: list[float] = MISSING
    acceleration_limits: list[float] = MISSING
    jerk_limits: list[float] = MISSING
    deviation_weights: list[float] = MISSING
    tcps: list[TcpCfg] = MISSING
    workspace: WorkspaceCfg = field(default_factory=WorkspaceCfg)
    floor_z: float = 0.0


@dataclass
class DatasetCfg:
    """A dataset (``conf/dataset/*.yaml``): its kind, directory, train / test sizes, seed and generator parameters."""

    name: str = MISSING
    kind: str = MISSING  # random | target_point | ball_balancing | imported
    path: str = MISSING  # directory of the dataset on disk (relative paths: to the working directory)
    num_train: int = 1000
    num_test: int = 200
    seed: int = 0
    params: dict[str, Any] = field(default_factory=dict)  # generator-specific overrides
    out_of_limits: str = "refuse"  # paths leaving the robot's position limits: refuse | clip (pathrl.dataset.io)


@dataclass
class KnotsCfg:
    """How stored paths are resampled into knots (``conf/knots/*.yaml``): strategy, spacing (rad) and knots in the
    state."""

    name: str = MISSING
    strategy: str = "curvature"  # curvature | distance | file
    spacing: float = 0.3
    base_spacing: float = 0.1
    n_state: int = 9


@dataclass
class DatasetAppCfg:
    """``pathrl-dataset generate``."""

    robot: RobotCfg = field(default_factory=RobotCfg)
    dataset: DatasetCfg = field(default_factory=DatasetCfg)
    workers: int = 2
    overwrite: bool = False


@dataclass
class ToppraAppCfg:
    """``pathrl-toppra``."""

    robot: RobotCfg = field(default_factory=RobotCfg)
    dataset: DatasetCfg = field(default_factory=DatasetCfg)
    knots: KnotsCfg = field(default_factory=KnotsCfg)
    split: str = "test"
    segments: str = "full"  # full | paper
    episodes: int | None = None  # default: number of paths (full) or 1200 (paper)
    seed: int = 0
    control_rate: float = 240.0
    workers: int = 1
    out: str | None = None
    ruckig: bool = False  # also track each plan with Ruckig under the jerk limits (pathrl.baselines.ruckig_track)


@dataclass
class EvalDatasetCfg:
    """``pathrl-eval``'s dataset: by ``name`` (``data/<the run's robot>/<name>``) or ``path``; neither: the run's."""

    name: str | None = None
    path: str | None = None
    out_of_limits: str = "refuse"  # refuse | clip (pathrl.dataset.io)


@dataclass
class EvalAppCfg:
    """``pathrl-eval``."""

    run_dir: str = MISSING  # a training run or a model directory
    dataset: EvalDatasetCfg = field(default_factory=EvalDatasetCfg)
    split: str = "test"
    episodes: int | None = None  # default: paths of the split (full) or 1200 (paper)
    segments: str = "paper"  # paper | full
    seed: int = 0
    out: str | None = None  # metrics.json / episodes.mcap; default: run_dir (models/<family>/<x>: runs/eval/<x>)
    write_models: bool = False  # allow `out` inside models/ (shipped policies are not written to unless asked)
    record: bool = True
    num_envs: int = 1200
    task: TaskCfg | None = None  # group conf/task: a feedback task added to a run trained without one (its name)
    backend: str = "pybullet"  # pybullet | analytic (runs with a task)
    compile_limits: bool = False
    open_loop: bool = False  # freeze the task's sensor at its first value of each episode
    checkpoint: str | None = None  # model_K.pt of a training run; default: its latest
    workers: int | None = None  # PyBullet worker processes of a TrueAdapt run; default: its config's


@dataclass
class ExportDatasetCfg:
    """``pathrl-export``'s dataset: its test split's states check the exports."""

    path: str | None = None  # default: the run's dataset, else the committed datasets/<robot>/<its name>


@dataclass
class ExportAppCfg:
    """``pathrl-export``."""

    run_dir: str = MISSING  # a training run or a model directory
    out: str | None = None  # directory of actor.pt, actor.onnx, export.json; default: <run_dir>/export
    dataset: ExportDatasetCfg = field(default_factory=ExportDatasetCfg)
    observations: int = 1000  # recorded states the exports are checked on


@dataclass
class RewardCfg:
    """A reward (``conf/reward/*.yaml``): its terms, each with its weight and parameters."""

    name: str = MISSING
    terms: dict[str, dict[str, float]] = field(default_factory=dict)  # {term: {weight, <params>}}


@dataclass
class BallCurriculumCfg:
    """A curriculum on the ball (``task.curriculum``; analytic ball, training only): new balls start with their
    rolling friction multiplied by ``friction_scale`` and their start position by ``start_spread`` (0: the plate's
    centre); both move log-linearly (friction) and linearly (spread) to the task's own values (1, 1) at iteration
    ``iterations``, and stay there. It depends only on the iteration, so a resumed run continues it."""

    iterations: int = 1000
    friction_scale: float = 1.0  # >= 1: balls that roll less at first
    start_spread: float = 1.0  # in [0, 1]: balls that start nearer the centre at first


@dataclass
class RewardCurriculumCfg:
    """A curriculum on reward term weights (``reward_curriculum``; training only): the term ``term`` (and each term in
    ``also``) starts at weight ``initial`` and moves linearly to its configured weight in the reward, reached at
    iteration ``iterations``. It depends only on the iteration, so a resumed run continues it."""

    term: str = MISSING
    initial: float = MISSING
    iterations: int = 1000
    also: list[str] = field(default_factory=list)  # more terms moved alike (deviation_mean beside deviation_max)


@dataclass
class TaskCfg:
    """Sensory-feedback task (``conf/task/*.yaml``): ``feedback: null`` is plain path tracking."""

    name: str = "tracking"
    feedback: str | None = None  # ball_on_plate
    backend: str = "analytic"  # analytic (batched torch model, training) | pybullet (worker processes)
    workers: int = 2  # pybullet worker processes
    observe: bool = True  # sensor values in the state
    fail_terminates: bool = True  # the task's failure (ball off the plate) ends the episode
    imu: bool = False  # ball_on_plate: the plate's inertial sensor reading joins the state (feedback.PlateIMU)
    critic_obs: bool = False  # an asymmetric critic: a privileged group "critic" (PathTrackingEnv.critic_observation)
    adapt: dict[str, Any] = field(default_factory=dict)  # TrueAdapt task settings (pathrl.envs.trueadapt); {}: none
    curriculum: BallCurriculumCfg | None = None  # ball_on_plate, analytic: easier balls first (BallCurriculumCfg)


@dataclass
class StdAnnealCfg:
    """Cap on the policy's action noise: from ``start`` (fraction of the iterations) it falls log-linearly from the
    initial std to ``final`` at the last iteration."""

    final: float = 0.03  # std cap at the last iteration (action units)
    start: float = 0.5  # fraction of ``iterations`` after which the cap starts to fall


@dataclass
class LrDecayCfg:
    """The learning rate falls log-linearly from ``agent.algorithm.learning_rate`` at ``start`` (fraction of the
    iterations) to ``final`` at the last iteration; ``final: null`` (the default) leaves the rate to the algorithm.
    PPO needs ``agent.algorithm.schedule: fixed`` with it (the adaptive schedule would overwrite it)."""

    final: float | None = None  # learning rate at the last iteration (null: no decay)
    start: float = 0.0  # fraction of ``iterations`` after which it starts to fall


@dataclass
class CriticWarmupCfg:
    """The first ``iterations`` iterations of a warm-started run train only the critic; the actor then starts at
    ``learning_rate`` (null: ``agent.algorithm.learning_rate``). ``freeze_normalizer`` keeps the actor's
    observation normaliser as loaded for the whole run (a fine-tune that should not move its inputs)."""

    iterations: int = 0
    learning_rate: float | None = None
    freeze_normalizer: bool = False


@dataclass
class TrainAppCfg:
    """``pathrl-train``."""

    robot: RobotCfg = field(default_factory=RobotCfg)
    dataset: DatasetCfg = field(default_factory=DatasetCfg)
    knots: KnotsCfg = field(default_factory=KnotsCfg)
    reward: RewardCfg = field(default_factory=RewardCfg)
    env: EnvSettings = field(default_factory=EnvSettings)
    task: TaskCfg = field(default_factory=TaskCfg)
    agent: dict[str, Any] = field(default_factory=dict)  # RSL-RL train cfg, keys verbatim
    experiment: str = MISSING
    config_version: int = CONFIG_VERSION  # layout of the saved config.yaml (pathrl.config.migrate)
    seed: int = 0
    device: str = "cpu"
    threads: int = 2
    compile_limits: bool = True  # torch.compile the limit kernels (pathrl.limits.kernels)
    native_limits: bool = True  # native C valid range and env step where available (pathrl.limits.backend)
    iterations: int = 400
    resume: bool = False
    run_dir: str = MISSING
    std_anneal: StdAnnealCfg | None = field(default_factory=lambda: StdAnnealCfg())
    # bfloat16 hidden layers switch to float32 after this fraction of the iterations (null: never)
    float32_from: float | None = None
    init_from: str | None = None  # warm start: actor/critic weights of this run or model dir (new inputs start at 0)
    critic_warmup: CriticWarmupCfg = field(default_factory=CriticWarmupCfg)  # a new critic learns alone first
    teacher: dict[str, Any] = field(default_factory=dict)  # agent=distillation: the labelling controller (name: tray)
    # PPO on a residual over a controller: {scale, controller: {name: tray, ...}} (pathrl.policy.residual)
    residual: dict[str, Any] = field(default_factory=dict)
    path_change: PathChangeCfg | None = None  # path changes during training (path_change=train); None: none
    # before PPO, search the warm-started actor's output offsets on the training return ({episodes, max_evals,
    # bound, seed}; pathrl.train.bias_search); empty: none
    bias_search: dict[str, Any] = field(default_factory=dict)
    lr_decay: LrDecayCfg = field(default_factory=LrDecayCfg)  # a falling learning rate (lr_decay.final=1e-5)
    # one reward term's weight moved from another value to the reward's own (pathrl.train.curricula); None: none
    reward_curriculum: RewardCurriculumCfg | None = None


def train_app_cfg(values: Mapping[str, Any]) -> TrainAppCfg:
    """The typed ``pathrl-train`` config of a resolved run config (a mapping with the schema's keys), each value
    converted to its field's type; a one-line ValueError for a value that does not convert (``iterations: abc``)."""
    node = OmegaConf.structured(TrainAppCfg)
    OmegaConf.set_readonly(node.env, None)  # the env group's frozen settings class: filled in here
    try:
        return OmegaConf.to_object(OmegaConf.merge(node, dict(values)))  # type: ignore[return-value]
    except OmegaConfBaseException as exc:
        key = getattr(exc, "full_key", None)
        raise ValueError(f"{key + ': ' if key else ''}{str(exc).strip().splitlines()[0]}") from None


def config_dict(cfg: Any) -> dict[str, Any]:
    """A typed config (:class:`TrainAppCfg`) as the plain dict Hydra composes and a run saves (``config.yaml``): the
    schema's key order, free-form groups (``agent``, ``teacher``, ...) as given."""
    return OmegaConf.to_container(OmegaConf.structured(cfg), resolve=True)  # type: ignore[return-value]
