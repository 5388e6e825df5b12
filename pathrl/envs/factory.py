"""Config glue of the tracking env, shared by training, evaluation and deployment: a config's task group with the
keys saved runs lack (:func:`task_cfg`) and the task's feedback source (:func:`make_feedback`). The env settings of
a run config are :meth:`pathrl.envs.tracking_cfg.TrackingEnvCfg.from_run`; saved configs are brought up to date by
:mod:`pathrl.config.migrate` (:data:`~pathrl.config.migrate.NO_TASK`, :data:`~pathrl.config.migrate.ADDED_KEYS`,
re-exported here). Which env a task builds is decided by the task registry (:mod:`pathrl.envs.registry`,
:func:`~pathrl.envs.registry.make_env`)."""

from __future__ import annotations

from typing import Any

from pathrl.config.migrate import ADDED_KEYS, NO_TASK
from pathrl.robot.model import RobotSpec

__all__ = ["ADDED_KEYS", "FEEDBACKS", "FEEDBACK_BACKENDS", "NO_TASK", "build_env", "is_trueadapt", "make_feedback",
           "task_cfg"]

FEEDBACK_BACKENDS = ("analytic", "pybullet")
FEEDBACKS = ("ball_on_plate", "standing")


def task_cfg(cfg: dict[str, Any]) -> dict[str, Any]:
    """The ``task`` group of a config with the keys of runs saved before tasks existed filled in (:data:`NO_TASK`)."""
    return {**NO_TASK, **(cfg.get("task") or {})}


def is_trueadapt(cfg: dict[str, Any]) -> bool:
    """Whether a config's task is a TrueAdapt trajectory adaptation (its registered task; ``task.adapt`` set)."""
    from pathrl.envs.registry import get_task

    return get_task(cfg).adapt


def make_feedback(cfg: dict[str, Any], robot: RobotSpec, num_envs: int, seed: int, backend: str | None = None,
                  device: str | None = None):
    """The feedback source of a config's task (None for plain tracking); `backend` overrides task.backend. `device`:
    the env's (default: the config's); the analytic ball is built there, PyBullet refuses any but the CPU."""
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
        if backend != "pybullet":
            raise ValueError("task standing: no analytic model of a standing robot exists; use task.backend=pybullet")
        if not robot.name.startswith("armar4"):
            raise ValueError(f"task standing is for ARMAR-4 (armar4, armar4_legs), not {robot.name}")
        from pathrl.sim.vec import PyBulletStanding

        return PyBulletStanding(robot, num_envs, rate, seed=seed, workers=int(t["workers"]))
    if backend == "analytic":
        from pathrl.envs.feedback import AnalyticBall

        return AnalyticBall(robot, num_envs, rate, seed=seed, device=device, imu=bool(t["imu"]))
    if backend == "pybullet":
        from pathrl.sim.vec import PyBulletBall

        return PyBulletBall(robot, num_envs, rate, seed=seed, workers=int(t["workers"]), imu=bool(t["imu"]))
    raise ValueError(f"task.backend: expected one of {list(FEEDBACK_BACKENDS)}, got {backend!r}")


def build_env(
    cfg: dict[str, Any],
    split: str = "train",
    num_envs: int | None = None,
    dataset_path: str | None = None,
    knot_gap_norm: float | None = None,
    seed: int | None = None,
):
    """The env of a resolved config's task on a dataset split; kept for callers of the old name, the same as
    :func:`pathrl.envs.registry.make_env`."""
    from pathrl.envs.registry import make_env

    return make_env(cfg, split, num_envs=num_envs, dataset_path=dataset_path, knot_gap_norm=knot_gap_norm, seed=seed)
