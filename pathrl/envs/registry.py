"""The task registry: every task a run config can name (``task.name``, ``conf/task/<name>.yaml``) and how its env
is built. Training, evaluation and the CLIs build envs through :func:`make_env` and check configs through
:func:`check_task`; nothing else decides by the task's keys which env a config means.

Tasks:
  tracking            plain path tracking (:class:`~pathrl.envs.tracking.PathTrackingEnv`, no feedback)
  ball_on_plate       path tracking with a ball on a plate at the flange (``task.backend`` analytic | pybullet)
  standing            path tracking of ARMAR-4 standing free on the floor (``task.backend`` pybullet | analytic)
  trueadapt_on_plate  TrueAdapt trajectory adaptation, ball kept off the plate's border
  trueadapt_in_place  TrueAdapt trajectory adaptation, ball kept near its start
                      (both :class:`~pathrl.envs.trueadapt.TrueAdaptEnv`)

Saved runs keep loading: a config without ``task`` is the plain tracking task (:data:`pathrl.config.migrate.NO_TASK`,
through :func:`task_cfg`), and the names above are the ones every shipped run was saved with. A task's feedback source
is built by :func:`make_feedback`; the env settings of a run config are
:meth:`pathrl.envs.tracking_cfg.TrackingEnvCfg.from_run`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from pathrl.config.migrate import NO_TASK
from pathrl.envs.device import EVAL_DEVICE
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.paths.pathset import PathSet
from pathrl.robot.kinematics import ForwardKinematics
from pathrl.robot.model import RobotSpec, load_robot

__all__ = ["EVAL_ENV", "FEEDBACKS", "FEEDBACK_BACKENDS", "TASKS", "EnvRequest", "Task", "check_task", "get_task",
           "make_env", "make_feedback", "task_cfg", "task_names", "tracking_paths"]

#: The feedback sources a task may name (``task.feedback``) and the simulators behind them (``task.backend``).
FEEDBACKS = ("ball_on_plate", "standing")
FEEDBACK_BACKENDS = ("analytic", "pybullet")

#: Env settings of an evaluation (and of deployment): no auto-reset, the evaluation device (the CPU, whatever device
#: the run was trained on), and no deviation or task-failure cut-off, so that every episode runs to its end or budget
#: and a policy that leaves the path is not credited with a short episode (as the authors evaluated).
EVAL_ENV: dict[str, Any] = {"autoreset": False, "device": EVAL_DEVICE, "max_deviation": None,
                            "fail_terminates": False}


@dataclass(frozen=True)
class EnvRequest:
    """What a caller asks of :func:`make_env` beyond the config: the dataset split and the overrides of
    evaluation (a pre-loaded path bank, the feedback simulator, an open-loop sensor, env settings)."""

    split: str = "train"
    num_envs: int | None = None  # None: env.num_envs
    seed: int | None = None  # None: the config's seed
    dataset_path: str | None = None  # None: dataset.path
    knot_gap_norm: float | None = None  # None: the path bank's largest knot gap (tracking tasks)
    paths: PathSet | None = None  # a loaded path bank instead of dataset_path (tracking tasks)
    robot: RobotSpec | None = None  # the loaded robot (None: loaded from the config)
    backend: str | None = None  # feedback simulator instead of task.backend (analytic | pybullet)
    open_loop: bool = False  # the task's sensor keeps its first value of each episode
    reward: bool = True  # False: no reward terms (a follower or an export computes no reward; tracking tasks)
    overrides: tuple[tuple[str, Any], ...] = ()  # env cfg fields to replace (e.g. EVAL_ENV)


@dataclass(frozen=True)
class Task:
    """One registered task: its feedback source, whether it is a TrueAdapt task, and its builder and checker."""

    name: str
    feedback: str | None  # the feedback source the task needs (task.feedback); None: none
    adapt: bool  # a TrueAdapt trajectory-adaptation task (task.adapt set)
    build: Callable[[dict[str, Any], EnvRequest], Any]  # (resolved config, request) -> env
    check: Callable[[dict[str, Any]], None]  # refuse a bad config before any data is read (ValueError)
    summary: str


def task_cfg(cfg: dict[str, Any]) -> dict[str, Any]:
    """The ``task`` group of a config with the keys of runs saved before tasks existed filled in (:data:`NO_TASK`)."""
    return {**NO_TASK, **(cfg.get("task") or {})}


def make_feedback(cfg: dict[str, Any], robot: RobotSpec, num_envs: int, seed: int, backend: str | None = None,
                  device: str | None = None, fk: ForwardKinematics | None = None):
    """The feedback source of a config's task (None for plain tracking); `backend` overrides task.backend. `device`:
    the env's (default: the config's); the analytic models are built there, PyBullet refuses any but the CPU. `fk`:
    the env's forward kinematics, which the feedback shares (None: it builds its own)."""
    t = task_cfg(cfg)
    if t["feedback"] is None:
        return None
    if t["feedback"] not in FEEDBACKS:
        raise ValueError(f"task.feedback: unknown {t['feedback']!r}; known: {list(FEEDBACKS)}")
    backend = backend or t["backend"]
    device = str(cfg.get("device", "cpu") if device is None else device)
    if backend == "pybullet":
        from pathrl.envs.device import check_run_device

        check_run_device({"device": device, "task": {**t, "backend": backend}})
    rate = float(cfg["env"]["control_rate"])
    if t["imu"] and t["feedback"] != "ball_on_plate":
        raise ValueError(f"task.imu: the plate sensor exists only for task ball_on_plate, not {t['feedback']!r}")
    if t["feedback"] == "standing":
        if not robot.name.startswith("armar4"):
            raise ValueError(f"task standing is for ARMAR-4 (armar4, armar4_legs), not {robot.name}")
        if backend == "analytic":  # the batched torch model (training); PyBullet is the reference (evaluation)
            from pathrl.sim.standing import AnalyticStanding

            return AnalyticStanding(robot, num_envs, rate, seed=seed, device=device, fk=fk)
        if backend == "pybullet":
            from pathrl.sim.vec import PyBulletStanding

            return PyBulletStanding(robot, num_envs, rate, seed=seed, workers=int(t["workers"]))
        raise ValueError(f"task.backend: expected one of {list(FEEDBACK_BACKENDS)}, got {backend!r}")
    if backend == "analytic":
        from pathrl.sim.feedback import AnalyticBall

        return AnalyticBall(robot, num_envs, rate, seed=seed, device=device, imu=bool(t["imu"]), fk=fk)
    if backend == "pybullet":
        from pathrl.sim.vec import PyBulletBall

        return PyBulletBall(robot, num_envs, rate, seed=seed, workers=int(t["workers"]), imu=bool(t["imu"]), fk=fk)
    raise ValueError(f"task.backend: expected one of {list(FEEDBACK_BACKENDS)}, got {backend!r}")


def tracking_paths(cfg: dict[str, Any], split: str, dataset_path: str | None = None,
                   robot: RobotSpec | None = None) -> PathSet:
    """The paths of `split` a tracking env of run config `cfg` is built on: `dataset_path` (default the config's
    ``dataset.path``) under the run's knot strategy and its ``dataset.out_of_limits`` rule (as it was trained).
    DatasetError / OSError on a bad dataset."""
    from pathrl.dataset.io import load_pathset
    from pathrl.paths.knots import KnotStrategy

    return load_pathset(dataset_path or cfg["dataset"]["path"], split, KnotStrategy.from_cfg(cfg["knots"]),
                        robot=robot or load_robot(cfg["robot"]),
                        out_of_limits=str(cfg["dataset"].get("out_of_limits", "refuse")))


def _build_tracking(cfg: dict[str, Any], req: EnvRequest):
    """A :class:`PathTrackingEnv` (with the task's feedback source, if any) on the requested paths."""
    from pathrl.envs.tracking import PathTrackingEnv
    from pathrl.sim.feedback import FrozenSensor

    robot = req.robot or load_robot(cfg["robot"])
    paths = req.paths if req.paths is not None else tracking_paths(cfg, req.split, req.dataset_path, robot)
    env_cfg = replace(TrackingEnvCfg.from_run(cfg, req.num_envs, req.seed, req.knot_gap_norm), **dict(req.overrides))
    # the env's one kinematics object, shared with its feedback; without a feedback the env builds it when first used
    fk = ForwardKinematics(robot, device=env_cfg.device) if task_cfg(cfg)["feedback"] is not None else None
    feedback = make_feedback(cfg, robot, env_cfg.num_envs, env_cfg.seed, req.backend, device=env_cfg.device, fk=fk)
    if req.open_loop:
        if feedback is None:
            raise ValueError("open_loop=true: the run has no feedback task to freeze (give task=...)")
        feedback = FrozenSensor(feedback)
    try:
        terms = build_reward_terms(cfg["reward"]["terms"]) if req.reward else []
        return PathTrackingEnv(env_cfg, robot, paths, terms, feedback, fk)
    except BaseException:
        if feedback is not None:  # simulator processes
            feedback.close()
        raise


def _check_tracking(cfg: dict[str, Any]) -> None:
    TrackingEnvCfg.from_run(cfg)  # the env's values (TrackingEnvCfg checks them); the dataset is checked by the run
    build_reward_terms(cfg["reward"]["terms"])


def _build_trueadapt(cfg: dict[str, Any], req: EnvRequest):
    """A :class:`TrueAdaptEnv` on the requested trajectory split (open loop: the ball is not observed)."""
    from pathrl.envs.trueadapt import build_trueadapt_env

    if req.paths is not None:
        raise ValueError("a TrueAdapt task runs on trajectories, not on a path bank")
    if not req.reward:
        raise ValueError("a TrueAdapt env always computes its reward (its task term decides failures)")
    if req.backend is not None:
        cfg = {**cfg, "task": {**cfg["task"], "backend": req.backend}}
    overrides = dict(req.overrides)
    if req.open_loop:
        overrides["obs_ball"] = False
    return build_trueadapt_env(cfg, req.split, req.num_envs, req.dataset_path, req.seed, **overrides)


def _check_trueadapt(cfg: dict[str, Any]) -> None:
    from pathrl.envs.trueadapt import check_adapt_cfg

    check_adapt_cfg(cfg)


TASKS: dict[str, Task] = {t.name: t for t in (
    Task("tracking", None, False, _build_tracking, _check_tracking, "plain path tracking"),
    Task("ball_on_plate", "ball_on_plate", False, _build_tracking, _check_tracking,
         "path tracking with a ball on a plate at the flange"),
    Task("standing", "standing", False, _build_tracking, _check_tracking, "path tracking of ARMAR-4 standing free"),
    Task("trueadapt_on_plate", "ball_on_plate", True, _build_trueadapt, _check_trueadapt,
         "TrueAdapt: adapt a trajectory, keep the ball off the plate's border"),
    Task("trueadapt_in_place", "ball_on_plate", True, _build_trueadapt, _check_trueadapt,
         "TrueAdapt: adapt a trajectory, keep the ball near its start"),
)}


def task_names() -> list[str]:
    """The registered task names (``task=<name>``)."""
    return list(TASKS)


def get_task(cfg: dict[str, Any]) -> Task:
    """The registered task of a resolved run config (no ``task``: plain tracking); a one-line ValueError for an
    unknown name, or for a config whose ``task.feedback`` / ``task.adapt`` do not fit the named task."""
    t = task_cfg(cfg)
    task = TASKS.get(t["name"])
    if task is None:
        raise ValueError(f"task.name: unknown task {t['name']!r}; known: {', '.join(TASKS)}")
    if t["feedback"] != task.feedback:
        raise ValueError(f"task {task.name}: task.feedback must be {task.feedback!r}, got {t['feedback']!r}")
    if bool(t.get("adapt")) != task.adapt:
        raise ValueError(f"task {task.name}: task.adapt must be {'set' if task.adapt else 'empty'} for this task")
    return task


def check_task(cfg: dict[str, Any]) -> Task:
    """Refuse a config whose task, env or reward settings are bad, before any data is read (one-line ValueError);
    returns its task."""
    task = get_task(cfg)
    task.check(cfg)
    return task


def make_env(cfg: dict[str, Any], request: EnvRequest = EnvRequest(), **overrides: Any):
    """The env of a resolved run config's task as `request` asks (:class:`EnvRequest`: the dataset split, its
    overrides); `overrides` replace env settings too (after ``request.overrides``), e.g. ``**EVAL_ENV``."""
    req = replace(request, overrides=request.overrides + tuple(overrides.items()))
    return get_task(cfg).build(cfg, req)
