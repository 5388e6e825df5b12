"""Config glue of the tracking env, shared by training, evaluation and deployment: the env settings of a resolved
run config (:func:`env_cfg_from`), its task group with the keys saved runs lack (:func:`task_cfg`, :data:`NO_TASK`,
:data:`ADDED_KEYS`) and the task's feedback source (:func:`make_feedback`). Which env a task builds is decided by
the task registry (:mod:`pathrl.envs.registry`, :func:`~pathrl.envs.registry.make_env`)."""

from __future__ import annotations

from typing import Any

from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.robot.model import RobotSpec

__all__ = ["ADDED_KEYS", "FEEDBACKS", "FEEDBACK_BACKENDS", "NO_TASK", "build_env", "env_cfg_from", "is_trueadapt",
           "make_feedback", "task_cfg"]


#: Config keys added after runs were saved, with the value that reproduces what those runs did: a saved config
#: without the key resumes under a config holding this value (and is evaluated with it, `env_cfg_from`).
ADDED_KEYS: dict[str, Any] = {"dataset.out_of_limits": "refuse",
                              "env.free_joint_actions": "linear", "env.posture_omega": 3.0, "task.imu": False,
                              "env.tcp_obs": False, "env.tcp_obs_box": [-1.0, 1.0, -1.0, 1.0, -0.7, 1.3],
                              "env.tcp_obs_error": 0.1, "teacher": {}, "residual": {}, "task.adapt": {},
                              "critic_warmup": {"iterations": 0, "learning_rate": None}}


def env_cfg_from(cfg: dict[str, Any], num_envs: int | None = None, seed: int | None = None,
                 knot_gap_norm: float | None = None) -> TrackingEnvCfg:
    """The tracking env settings of a resolved config (keys missing in saved runs take their :data:`ADDED_KEYS`
    value); `num_envs`, `seed`, `knot_gap_norm` replace the config's."""
    e, task = cfg["env"], task_cfg(cfg)
    return TrackingEnvCfg(
        num_envs=int(num_envs or e["num_envs"]),
        device=str(cfg.get("device", "cpu")),
        seed=int(cfg.get("seed", 0) if seed is None else seed),
        dt=float(e["dt"]),
        control_rate=float(e["control_rate"]),
        substeps=int(e["substeps"]),
        episode_budget_s=float(e["episode_budget_s"]),
        scale_budget=bool(e["scale_budget"]),
        segments=str(e["segments"]),
        start_range=tuple(float(x) for x in e["start_range"]),
        min_fraction=float(e["min_fraction"]),
        max_deviation=None if e["max_deviation"] is None else float(e["max_deviation"]),
        stop_tolerance=float(e["stop_tolerance"]),
        stop_bonus=bool(e["stop_bonus"]),
        knot_gap_norm=knot_gap_norm,
        n_state=int(cfg["knots"]["n_state"]),
        knot_obs=str(e.get("knot_obs", "relative")),
        end_obs=bool(e.get("end_obs", False)),  # runs saved before these options existed did not have them
        end_tolerance=None if e.get("end_tolerance") is None else float(e["end_tolerance"]),
        feedback_obs=bool(task["observe"]),
        fail_terminates=bool(task["fail_terminates"]),
        free_joint_actions=str(e.get("free_joint_actions", ADDED_KEYS["env.free_joint_actions"])),
        posture_omega=float(e.get("posture_omega", ADDED_KEYS["env.posture_omega"])),
        tcp_obs=bool(e.get("tcp_obs", ADDED_KEYS["env.tcp_obs"])),
        tcp_obs_box=tuple(float(x) for x in e.get("tcp_obs_box", ADDED_KEYS["env.tcp_obs_box"])),
        tcp_obs_error=float(e.get("tcp_obs_error", ADDED_KEYS["env.tcp_obs_error"])),
    )


#: The task of configs saved before tasks existed (plain tracking).
NO_TASK = {"name": "tracking", "feedback": None, "backend": "analytic", "workers": 2, "observe": True,
           "fail_terminates": True, "imu": False}
FEEDBACK_BACKENDS = ("analytic", "pybullet")
FEEDBACKS = ("ball_on_plate", "standing")


def task_cfg(cfg: dict[str, Any]) -> dict[str, Any]:
    """The ``task`` group of a config with the keys of runs saved before tasks existed filled in (:data:`NO_TASK`)."""
    return {**NO_TASK, **(cfg.get("task") or {})}


def is_trueadapt(cfg: dict[str, Any]) -> bool:
    """Whether a config's task is a TrueAdapt trajectory adaptation (its registered task; ``task.adapt`` set)."""
    from pathrl.envs.registry import get_task

    return get_task(cfg).adapt


def make_feedback(cfg: dict[str, Any], robot: RobotSpec, num_envs: int, seed: int, backend: str | None = None):
    """The feedback source of a config's task (None for plain tracking); `backend` overrides task.backend."""
    t = task_cfg(cfg)
    if t["feedback"] is None:
        return None
    if t["feedback"] not in FEEDBACKS:
        raise ValueError(f"task.feedback: unknown {t['feedback']!r}; known: {list(FEEDBACKS)}")
    backend = backend or t["backend"]
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

        return AnalyticBall(robot, num_envs, rate, seed=seed, device=str(cfg.get("device", "cpu")), imu=bool(t["imu"]))
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
