"""Speed of the env and of what it runs (:mod:`pathrl.bench`): env steps/s batched (native, compiled torch or eager
limit code; 1 or 2 threads) and as the single-env reference, PPO iterations, one decision of policy + limits, the
ball task analytic or in PyBullet, PyBullet physics. Paths are synthetic (:func:`synthetic_knots`)."""

from __future__ import annotations

import contextlib
import time

import numpy as np
import torch

from pathrl import native
from pathrl.config.paths import CONF_DIR
from pathrl.envs.rewards import build_reward_terms
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.limits.backend import LimitBackend, current
from pathrl.paths.pathset import build_pathset
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.model import RobotSpec

__all__ = ["REWARD", "bench_ball_task", "bench_decision", "bench_env", "bench_physics", "bench_ppo_iteration",
           "bench_reference", "limit_code", "make_env", "run_steps", "synthetic_knots"]

REWARD = {"path_length": {"weight": 2.0}, "deviation_max": {"weight": 0.9}, "deviation_mean": {"weight": 0.9},
          "action_saturation": {"weight": 0.4}}


def synthetic_knots(robot: RobotSpec, n_paths: int, seed: int = 0) -> list[np.ndarray]:
    """Smooth random paths (sums of sinusoids) inside the middle of each path joint's range."""
    rng = np.random.default_rng(seed)
    lim = robot.pos_limits[robot.path_index]
    mid, half = lim.mean(1), 0.4 * (lim[:, 1] - lim[:, 0]) / 2
    t = np.linspace(0, 1, 150)[:, None]
    out = []
    for _ in range(n_paths):
        f = rng.uniform(0.5, 2.0, (1, len(mid)))
        ph = rng.uniform(0, 2 * np.pi, (1, len(mid)))
        out.append(mid + half * np.sin(2 * np.pi * f * t + ph))
    return out


def make_env(robot: RobotSpec, num_envs: int, seed: int = 0, limit_backend: LimitBackend | None = None
             ) -> PathTrackingEnv:
    """The benchmark env; `limit_backend` None: it follows the backend in effect (:func:`limit_code`)."""
    knots = synthetic_knots(robot, 64, seed)
    paths = build_pathset(knots, [f"p{i}" for i in range(len(knots))])
    cfg = TrackingEnvCfg(num_envs=num_envs, seed=seed, n_state=9, limit_backend=limit_backend)
    return PathTrackingEnv(cfg, robot, paths, build_reward_terms(REWARD))


def run_steps(env: PathTrackingEnv, seconds: float, warmup: int) -> tuple[int, float]:
    """Step `env` with 8 cycled random action batches for `seconds` after `warmup` steps: (steps, env-steps/s)."""
    gen = torch.Generator().manual_seed(0)
    actions = [torch.rand(env.num_envs, env.num_actions, generator=gen) * 2 - 1 for _ in range(8)]
    for k in range(warmup):
        env.step(actions[k % 8])
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        env.step(actions[steps % 8])
        steps += 1
    return steps, steps * env.num_envs / (time.perf_counter() - t0)


@contextlib.contextmanager
def limit_code(mode: str, threads: int = 1, native_threads: int | None = None):
    """Native code (valid range, env step), `torch` (compiled kernels) or `eager`, and torch threads, in the block."""
    if mode not in ("native", "torch", "eager"):
        raise ValueError(f"unknown limit code {mode!r}")
    before = torch.get_num_threads()
    native.set_threads(native_threads)
    torch.set_num_threads(threads)
    try:
        with LimitBackend(native=mode == "native", compiled=mode != "eager").active():
            yield
    finally:
        native.set_threads(None)
        torch.set_num_threads(before)


def bench_env(robot_name: str, num_envs: int, seconds: float, mode: str = "native", threads: int = 1,
              native_threads: int | None = None) -> dict:
    """Env steps per second of `num_envs` random-path tracking envs of robot `robot_name`, stepped for `seconds` (s)
    after a warm-up, with the limit code `mode` (native | torch | eager, :func:`limit_code`) on `threads` threads."""
    with limit_code(mode, threads, native_threads):
        if mode == "native" and not native.available():
            raise RuntimeError("the native limit code is not built (no C compiler?)")
        env = make_env(load_robot_by_name(robot_name), num_envs)
        steps, rate = run_steps(env, seconds, warmup=5 if mode == "eager" else 30)
    return {"robot": robot_name, "num_envs": num_envs, "limits": mode, "threads": threads,
            "native_threads": (native_threads or threads) if mode == "native" else None, "steps": steps,
            "env_steps_per_s": rate}


def bench_reference(robot_name: str, seconds: float) -> dict:
    """Steps per second of the one-env numpy reference env (:mod:`pathrl.envs.reference`) on one synthetic path of
    robot `robot_name`, random actions, over `seconds` (s)."""
    from pathrl.envs.reference import ReferencePath, ReferenceSettings, ReferenceTrackingEnv
    from pathrl.limits.braking import braking_acceleration
    from pathrl.limits.feasible import JointLimits

    robot = load_robot_by_name(robot_name)
    knots = synthetic_knots(robot, 1)[0]
    path = ReferencePath(knots)
    lim = JointLimits.from_robot(robot)

    def brake(p, v, a):
        t = [torch.as_tensor(x).unsqueeze(0) for x in (p, v, a)]
        return braking_acceleration(*t, lim, 0.1)[0].numpy()

    def make():
        settings = ReferenceSettings(float(np.diff(path.knot_s).max()))
        return ReferenceTrackingEnv(robot, path, 0.0, len(path.knots) - 1, build_reward_terms(REWARD), settings, brake)

    env = make()
    rng = np.random.default_rng(0)
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        r = env.step(rng.uniform(-1, 1, robot.dof))
        env.observation()
        steps += 1
        if r.terminated or r.time_out:
            env = make()
    dt = time.perf_counter() - t0
    return {"robot": robot_name, "steps": steps, "env_steps_per_s": steps / dt}


def bench_ppo_iteration(robot_name: str, num_envs: int, iterations: int, threads: int = 2,
                        hidden_dtype: str = "bfloat16") -> dict:
    """Seconds per PPO iteration of `conf/agent/ppo.yaml` (rollout + returns + update) with `threads` torch
    threads (``pathrl-train`` runs with 2) and the models' hidden layers in `hidden_dtype`, and the share of
    each phase: policy passes in the rollout (``act``), env steps, the update (``update``), the rest."""
    import yaml
    from rsl_rl.runners import OnPolicyRunner

    agent = yaml.safe_load((CONF_DIR / "agent" / "ppo.yaml").read_text())
    for model in ("actor", "critic"):
        agent[model]["hidden_dtype"] = hidden_dtype
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        env = make_env(load_robot_by_name(robot_name), num_envs)
        runner = OnPolicyRunner(env, agent, log_dir=None, device="cpu")
        runner.learn(3 if current().compiled else 1)  # rollouts run in inference mode: kernels compile again
        phases = {"act": 0.0, "env_step": 0.0, "update": 0.0}
        _time_calls(runner.alg, "act", phases)
        _time_calls(env, "step", phases, "env_step")
        _time_calls(runner.alg, "update", phases)
        t0 = time.perf_counter()
        runner.learn(iterations)
        dt = (time.perf_counter() - t0) / iterations
    finally:
        torch.set_num_threads(before)
    samples = agent["num_steps_per_env"] * num_envs
    share = {k: v / iterations / dt for k, v in phases.items()}
    share["other"] = 1.0 - sum(share.values())
    return {"robot": robot_name, "num_envs": num_envs, "steps_per_env": agent["num_steps_per_env"],
            "threads": threads, "hidden_dtype": hidden_dtype, "iterations": iterations, "s_per_iteration": dt,
            "samples_per_s": samples / dt, "share": share}


def _time_calls(obj, name: str, acc: dict[str, float], key: str | None = None) -> None:
    """Wrap `obj.name` so that its wall time adds up in `acc[key or name]`."""
    f = getattr(obj, name)

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        out = f(*args, **kwargs)
        acc[key or name] += time.perf_counter() - t0
        return out

    setattr(obj, name, timed)


def bench_decision(robot_name: str, repeats: int = 300, mode: str = "native") -> dict:
    """Time of one decision for one env: observation -> policy (MLP 256-128) -> limits -> setpoints."""
    with limit_code(mode):
        return _decision(robot_name, repeats) | {"limits": mode}


def _decision(robot_name: str, repeats: int) -> dict:
    from pathrl.limits.feasible import JointLimits, action_to_acceleration, valid_acceleration_range
    from pathrl.limits.integrate import interpolate_step

    robot = load_robot_by_name(robot_name)
    env = make_env(robot, 1)
    obs = env.get_observations()["policy"]
    mlp = torch.nn.Sequential(torch.nn.Linear(obs.shape[1], 256), torch.nn.ELU(), torch.nn.Linear(256, 128),
                              torch.nn.ELU(), torch.nn.Linear(128, robot.dof))
    lim = JointLimits.from_robot(robot)
    p, v, a = env.pos.clone(), env.vel.clone(), env.acc.clone()
    times = []
    with torch.inference_mode():
        for _ in range(repeats):
            t0 = time.perf_counter()
            act = mlp(obs).to(torch.float64)
            lo, hi = valid_acceleration_range(p, v, a, lim, 0.1)
            a1 = action_to_acceleration(act.clamp(-1, 1), lo, hi)
            interpolate_step(p, v, a, a1, 0.1, 24)
            times.append(time.perf_counter() - t0)
    t = np.array(times[50:])  # the first calls compile
    return {"robot": robot_name, "mean_ms": 1e3 * t.mean(), "max_ms": 1e3 * t.max(),
            "max_pct_of_step": 100 * t.max() / 0.1}


def bench_ball_task(backend: str, num_envs: int, seconds: float, workers: int = 2) -> dict:
    """Env steps/s of the ball-on-plate task (tracking + ball feedback) with the analytic torch ball or PyBullet
    (one client per env, `workers` processes): the same MDP, so the ratio is the price of simulating physics."""
    from pathrl.sim.feedback import AnalyticBall
    from pathrl.sim.vec import PyBulletBall

    robot = load_robot_by_name("iiwa7")
    knots = synthetic_knots(robot, 64)
    paths = build_pathset(knots, [f"p{i}" for i in range(len(knots))])
    cfg = TrackingEnvCfg(num_envs=num_envs, seed=0, n_state=9, fail_terminates=False)
    fb = (AnalyticBall(robot, num_envs, cfg.control_rate) if backend == "analytic"
          else PyBulletBall(robot, num_envs, cfg.control_rate, workers=workers))
    try:
        env = PathTrackingEnv(cfg, robot, paths, build_reward_terms({**REWARD, "ball_centre": {"weight": 1.0}}), fb)
        steps, rate = run_steps(env, seconds, warmup=3)
    finally:
        fb.close()
    return {"backend": backend, "num_envs": num_envs, "workers": workers if backend == "pybullet" else None,
            "steps": steps, "env_steps_per_s": rate}


def bench_physics(scene_name: str, seconds: float) -> dict:
    """PyBullet physics steps per second (240 Hz steps incl. motor commands) of one sensory-feedback scene."""
    import numpy as np

    if scene_name == "ball_on_plate":
        from pathrl.sim.ball_plate import BallOnPlateScene

        scene = BallOnPlateScene(load_robot_by_name("iiwa7"))
        q = np.array([0.0, 0.5, 0.0, -1.0, 0.0, -1.5, 0.0])
        scene.reset(q)
    else:
        from pathrl.sim.humanoid import StandingScene

        scene = StandingScene(load_robot_by_name("armar4_legs"))
        q = np.zeros(len(scene.joint_ids))
        scene.reset(q)
    block_q, block_v = np.tile(q, (24, 1)), np.zeros((24, len(q)))
    steps, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        scene.follow(block_q, block_v)
        steps += 24
    dt = time.perf_counter() - t0
    scene.close()
    return {"scene": scene_name, "physics_steps_per_s": steps / dt, "decisions_per_s": steps / 24 / dt}
