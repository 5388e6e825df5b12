"""Benchmarks (`make bench`): env steps/s (batched vs single-env reference), PPO iteration time, and the
time per decision of policy + limits for one env. Writes bench/results.json and prints a table.

Paths are synthetic smooth paths inside the joint limits (no dataset needed), so the numbers measure
the env itself. The valid acceleration range, most of a step, runs in one of three ways (``limits`` in
each result; a :class:`pathrl.limits.backend.LimitBackend`): ``native`` (the C build in ``pathrl/native``, the
default), ``torch`` (the torch reference with compiled kernels, ``pathrl.limits.kernels``) and ``eager`` (torch,
nothing compiled).
The env's fused step (also native in the first mode) and observation kernels are compiled in the first
two. Threads: 1; 2 (``*_threads2``: torch on both cores, as ``pathrl-train`` runs with ``threads: 2``; the
native code follows torch's count); and ``*_cores2``: torch on 1 thread, the native code on 2 (torch's
OpenMP workers spin between ops and compete with the native threads, so on 2 cores this is the faster
setup for stepping). Compilation happens in untimed warm-up steps. PPO iterations run with the models' hidden
layers in bfloat16 (the default) where the CPU has bfloat16 natively, else in float32 only
(``bfloat16_over_float32_layer``: the measured slowdown; emulated bfloat16 would take most of the bench's time).
``--quick``: tiny sizes.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import time
from dataclasses import asdict
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from pathrl import native  # noqa: E402
from pathrl.deploy.fuzz import fuzz_follower  # noqa: E402
from pathrl.envs.rewards import build_reward_terms  # noqa: E402
from pathrl.envs.tracking import PathTrackingEnv  # noqa: E402
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.eval.limit_fuzz import fuzz_env, fuzz_report  # noqa: E402
from pathrl.limits.backend import LimitBackend, current  # noqa: E402
from pathrl.paths.pathset import build_pathset  # noqa: E402
from pathrl.robot.external import load_robot_by_name
from pathrl.robot.model import RobotSpec  # noqa: E402
from pathrl.storage import write_json_atomic  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
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
    with limit_code(mode, threads, native_threads):
        if mode == "native" and not native.available():
            raise RuntimeError("the native limit code is not built (no C compiler?)")
        env = make_env(load_robot_by_name(robot_name), num_envs)
        steps, rate = run_steps(env, seconds, warmup=5 if mode == "eager" else 30)
    return {"robot": robot_name, "num_envs": num_envs, "limits": mode, "threads": threads,
            "native_threads": (native_threads or threads) if mode == "native" else None, "steps": steps,
            "env_steps_per_s": rate}


def bench_reference(robot_name: str, seconds: float) -> dict:
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

    agent = yaml.safe_load((ROOT / "conf/agent/ppo.yaml").read_text())
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


def _ms(wall: list[float], cpu: list[float]) -> dict:
    """Mean / p99 / max of wall-clock and thread CPU times (s) in ms: on a shared machine the wall clock includes
    the time the thread waited for a core, the CPU time does not."""
    w, c = 1e3 * np.asarray(wall), 1e3 * np.asarray(cpu)
    return {"mean_ms": w.mean(), "p99_ms": np.quantile(w, 0.99), "max_ms": w.max(),
            "cpu_mean_ms": c.mean(), "cpu_p99_ms": np.quantile(c, 0.99), "cpu_max_ms": c.max()}


def bench_follower(model: str, dataset: str, decisions: int = 400, changes: int = 100) -> dict:
    """Latency of :class:`pathrl.deploy.Follower` on one thread (warm-up excluded): `decide()` (the shipped policy,
    the env's step, the 24 setpoints; the final approach at path ends) decision after decision along test paths,
    and `replace_path` mid-path to a path from the robot to another test path (those inside the position range; the
    refused ones counted), given as knots and as a path `prepare`d beforehand."""
    from pathrl.dataset.io import load_dataset
    from pathrl.deploy import Follower, FollowerError

    torch.set_num_threads(1)
    follower = Follower.load(model)
    paths = load_dataset(dataset, follower.robot).splits["test"].knots
    wall, cpu, k = [], [], 0
    follower.reset(paths[0])
    while len(wall) < decisions + 50:
        if follower.done:
            k += 1
            follower.reset(paths[k % len(paths)])
        t0, c0 = time.perf_counter(), time.thread_time()
        follower.decide()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    res = {"model": model, "decisions": decisions, **_ms(wall[50:], cpu[50:])}
    idx = follower.robot.path_index
    for kind in ("knots", "prepared"):
        wall, cpu, refused, i = [], [], 0, 0
        while len(wall) < changes + 5:
            i += 1
            follower.reset(paths[i % len(paths)])
            for _ in range(10):
                follower.decide()
            new = np.vstack([follower.state[0][idx], paths[(i + 1) % len(paths)]])
            try:  # a straight line from the robot to another path's start: refused where its spline leaves the range
                prepared = follower.prepare(new)
            except FollowerError:
                refused += 1
                continue
            arg = prepared if kind == "prepared" else new
            t0, c0 = time.perf_counter(), time.thread_time()
            follower.replace_path(arg)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.thread_time() - c0)
        res[f"replace_path_{kind}"] = {"changes": changes, "refused": refused, **_ms(wall[5:], cpu[5:])}
    return res


def bench_follower_end(model: str, dataset: str, rate_hz: float = 240.0) -> dict:
    """Every test path followed to its end by :class:`pathrl.deploy.Follower` with setpoints at `rate_hz`: the
    final error (largest joint, rad) from the path's last knot, limit violations of every setpoint (position,
    velocity, acceleration, jerk), the duration and the final approach."""
    from pathrl.dataset.io import load_dataset
    from pathrl.deploy import Follower
    from pathrl.limits.check import limit_violations
    from pathrl.limits.feasible import JointLimits

    torch.set_num_threads(1)
    follower = Follower.load(model, control_rate=rate_hz)
    paths = load_dataset(dataset, follower.robot).splits["test"].knots
    lim, idx = JointLimits.from_robot(follower.robot), follower.robot.path_index
    errors, violations, durations, approach, from_rest, not_done = [], 0, [], [], 0, 0
    for knots in paths:
        follower.reset(knots)
        ps, vs, accs = ([torch.as_tensor(x)[None]] for x in follower.state)
        decisions = 0
        while decisions < 1000:
            sp, decisions = follower.decide(), decisions + 1
            for lst, x in zip((ps, vs, accs), (sp.position, sp.velocity, sp.acceleration), strict=True):
                lst.append(torch.as_tensor(x))
            if follower.done:
                break
        not_done += not follower.done
        violations += int(limit_violations(torch.cat(ps), torch.cat(vs), torch.cat(accs), lim, 1.0 / rate_hz)["total"])
        errors.append(float(np.abs(follower.state[0][idx] - knots[-1]).max()))
        durations.append(0.1 * decisions)
        approach.append(follower.final_approach_s)
        from_rest += follower.approach_from_rest
    e = np.asarray(errors)
    return {"model": model, "rate_hz": rate_hz, "paths": len(paths), "not_done": not_done,
            "final_error_max": e.max(), "final_error_mean": e.mean(), "violations": violations,
            "duration_mean_s": float(np.mean(durations)), "approach_mean_s": float(np.mean(approach)),
            "approach_max_s": float(np.max(approach)), "approaches_from_rest": from_rest}


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=5.0, help="time per env benchmark")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (tests)")
    ap.add_argument("--limits", default="native,torch,eager",
                    help="valid-range code to measure, comma-separated: native, torch (compiled), eager")
    ap.add_argument("--fuzz-steps", type=int, default=10_000_000,
                    help="adversarial limit fuzz: decision steps per robot (pathrl.eval.limit_fuzz)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results.json"))
    ap.add_argument("--follower-only", action="store_true",
                    help="only the follower: latency (decide, replace_path) and every test path to its end at "
                         "100, 240 and 500 Hz; merged into --out")
    ap.add_argument("--follower-fuzz-only", action="store_true",
                    help="only the follower fuzz (adversarial paths, path changes, stops, measured states; "
                         "pathrl.deploy.fuzz), with the load average in its entry; merged into --out")
    args = ap.parse_args()
    torch.set_num_threads(1)
    quick = args.quick
    sec = 0.5 if quick else args.seconds
    n = 256 if quick else 4096
    modes = tuple(args.limits.split(","))
    if not modes or any(m not in ("native", "torch", "eager") for m in modes):
        ap.error(f"--limits: expected a comma-separated subset of native,torch,eager, got {args.limits!r}")
    res = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "torch": torch.__version__,
                       "native_limits": native.available(), "load_avg_start": _load()}}
    if args.follower_fuzz_only:
        fuzz = {"follower_fuzz_iiwa7_random": _follower_fuzz(quick)}
        _merge(Path(args.out), fuzz)
        _print_follower({**res, **fuzz})
        return
    if args.follower_only:
        _follower_benches(res, quick)
        res["machine"]["load_avg_end"] = _load()
        _merge(Path(args.out), res)
        _print_follower(res)
        return
    suffix = {"native": "", "torch": "_torch", "eager": "_eager"}
    for robot in ("iiwa7", "armar4_legs"):
        for mode in modes:
            res[f"env_{robot}{suffix[mode]}"] = bench_env(robot, n, sec, mode)
        res[f"env_{robot}{suffix[modes[0]]}_threads2"] = bench_env(robot, n, sec, modes[0], threads=2)
        if modes[0] == "native":  # both cores for the native code, torch ops on one
            res[f"env_{robot}_cores2"] = bench_env(robot, n, sec, "native", threads=1, native_threads=2)
    for robot in ("iiwa7", "armar6", "armar4_legs"):
        for mode in modes:
            res[f"decision_{robot}{suffix[mode]}"] = bench_decision(robot, mode=mode)
    _follower_benches(res, quick)
    from pathrl.eval.trueadapt_realtime import measure as adapt_decision  # TrueAdapt: policy + valid range, 50 ms
    from pathrl.repro import trueadapt as adapt

    res["trueadapt_decision"] = adapt_decision(ROOT / "models" / adapt.REALTIME_MODEL,
                                               str(ROOT / "datasets" / adapt.ROBOT / adapt.REALTIME_DATA),
                                               100 if quick else 2000)
    main_key = f"env_iiwa7{suffix[modes[0]]}"
    res["reference_iiwa7"] = bench_reference("iiwa7", sec)
    ref_rate = res["reference_iiwa7"]["env_steps_per_s"]
    res["batched_over_reference_iiwa7"] = res[main_key]["env_steps_per_s"] / ref_rate
    from pathrl.policy.models import BFLOAT16_EMULATED, bfloat16_slowdown

    # bfloat16 hidden layers only where the CPU has them natively: emulated they run >10x slower (pathrl-train warns)
    res["bfloat16_over_float32_layer"] = bfloat16_slowdown()
    hidden = "float32" if res["bfloat16_over_float32_layer"] > BFLOAT16_EMULATED else "bfloat16"
    with limit_code(modes[0]):
        its = 1 if quick else 4
        for robot in ("iiwa7", "armar4_legs"):  # as pathrl-train runs: 2 threads, the default bfloat16 where native
            res[f"ppo_iteration_{robot}"] = bench_ppo_iteration(robot, n, its, hidden_dtype=hidden)
        # float32 hidden layers, 2 threads and 1 thread: what the bfloat16 hidden layers and the threads buy
        if hidden == "bfloat16":
            res["ppo_iteration_iiwa7_float32"] = bench_ppo_iteration("iiwa7", n, its, hidden_dtype="float32")
        res["ppo_iteration_iiwa7_float32_1thread"] = bench_ppo_iteration("iiwa7", n, its, 1, "float32")
    res["physics_ball_on_plate"] = bench_physics("ball_on_plate", sec)
    res["physics_armar4_standing"] = bench_physics("armar4_standing", sec)
    with limit_code(modes[0]):
        res["ball_task_analytic"] = bench_ball_task("analytic", n, sec)
        res["ball_task_pybullet"] = bench_ball_task("pybullet", 16 if quick else 64, sec)
    # Adversarial limit fuzz: >= --fuzz-steps decision steps per robot, every control-rate setpoint checked.
    fuzz_envs = 256 if quick else 4096
    fuzz_steps = -(-(20_000 if quick else args.fuzz_steps) // fuzz_envs)
    torch.set_num_threads(2)
    with limit_code(modes[0]):
        for robot in ("iiwa7", "armar6", "armar4_legs"):
            res[f"limit_fuzz_{robot}"] = fuzz_report([fuzz_env(robot, fuzz_steps, fuzz_envs, root=ROOT)])[robot]
    torch.set_num_threads(1)
    pyb = res["ball_task_pybullet"]["env_steps_per_s"]
    res["ball_task_analytic_over_pybullet"] = res["ball_task_analytic"]["env_steps_per_s"] / pyb
    # Both sides on both cores (the PyBullet env steps its scenes in 2 worker processes): the faster 2-core setup.
    two = max(res[k]["env_steps_per_s"] for k in (main_key + "_threads2", "env_iiwa7_cores2") if k in res)
    res["kinematic_tracking_over_pybullet_ball"] = two / pyb
    res["kinematic_tracking_1thread_over_pybullet_ball"] = res[main_key]["env_steps_per_s"] / pyb
    res["machine"]["load_avg_end"] = _load()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, res)
    _print(res, out)


def _load() -> list[float] | None:
    """The system's load average over 1, 5 and 15 min (runnable processes; on a shared machine the wall-clock
    latencies depend on it), or None where the platform has none."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


FOLLOWER_MODELS = (("models/iiwa7_random", "datasets/iiwa7/random"), ("models/armar6_random", "datasets/armar6/random"))
FOLLOWER_END = (("models/iiwa7_random", "datasets/iiwa7/random"),
                ("models/iiwa7_random_track_distill", "datasets/iiwa7/random"))


def _follower_benches(res: dict, quick: bool) -> None:
    """The follower's latency (both robots) and its path ends (iiwa7: both shipped random-path policies)."""
    for model, dataset in FOLLOWER_MODELS:
        res[f"follower_{Path(model).name}"] = bench_follower(model, dataset, 100 if quick else 400,
                                                             10 if quick else 100)
    if not quick:
        for model, dataset in FOLLOWER_END:
            for rate in (100, 240, 500):
                res[f"follower_end_{Path(model).name}_{rate}hz"] = bench_follower_end(model, dataset, rate)
    res["follower_fuzz_iiwa7_random"] = _follower_fuzz(quick)


def _follower_fuzz(quick: bool) -> dict:
    """The follower under adversarial paths, path changes, stops and measured states (pathrl.deploy.fuzz), 300 trials
    (10 with `quick`), with the load average at its start and end (its time depends on it)."""
    start = _load()
    fuzz = fuzz_follower(ROOT / "models" / "iiwa7_random", 10 if quick else 300)
    return {**asdict(fuzz), "model": "models/iiwa7_random", "load_avg": [start, _load()]}


def _merge(out: Path, res: dict) -> None:
    """Write `res` into the JSON file `out`, keeping its other entries (atomic)."""
    old = json.loads(out.read_text()) if out.is_file() else {}
    write_json_atomic(out, {**old, **res})


def _print_follower(res: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    load = res["machine"].get("load_avg_start")
    t = Table(title="pathrl.deploy.Follower, 1 thread (wall clock; CPU time of the thread)"
              + (f", load {load[0]:g} at the start" if load else ""))
    t.add_column("benchmark")
    t.add_column("result", justify="right")
    _follower_rows(t, res)
    Console().print(t)


def _follower_rows(t, res: dict) -> None:
    """Rows of the follower benchmarks."""
    for k in sorted(k for k in res if k.startswith("follower_") and "decisions" in res[k]):
        d = res[k]
        t.add_row(f"Follower.decide, {d['model']}",
                  f"{d['mean_ms']:.2f} ms mean, p99 {d['p99_ms']:.2f} (CPU p99 {d['cpu_p99_ms']:.2f})")
        for kind in ("knots", "prepared"):
            r = d.get(f"replace_path_{kind}")
            if r:
                t.add_row(f"Follower.replace_path ({kind}), {d['model']}",
                          f"{r['mean_ms']:.2f} ms mean, p99 {r['p99_ms']:.2f} (CPU p99 {r['cpu_p99_ms']:.2f})")
    for k in sorted(k for k in res if k.startswith("follower_end_")):
        d = res[k]
        t.add_row(f"Follower to the end, {d['model']}, {d['paths']} test paths at {d['rate_hz']:g} Hz",
                  f"final error max {d['final_error_max']:.1e} rad, {d['violations']} violations, "
                  f"{d['not_done']} not done, approach mean {d['approach_mean_s']:.2f} s")
    f = res.get("follower_fuzz_iiwa7_random")
    if f:
        t.add_row(f"Follower fuzz, {Path(f['model']).name}: {f['trials']} adversarial paths ({f['refused']} refused "
                  f"unclipped, all followed clipped), {f['path_changes']} path changes "
                  f"({f.get('path_changes_refused', 0)} refused), {f['stops']} stops, {f['bad_states_refused']} bad "
                  f"states refused, {f.get('measured_states', 0)} measured states ({f.get('measured_refused', 0)} "
                  f"refused, {f.get('measured_mishandled', 0)} mishandled), {f['crashes']} crashes",
                  f"{f['violations']} violations in {f['setpoints_checked']:,} setpoint values")


def _print(res: dict, out: Path) -> None:
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"pathrl benchmarks -> {out}")
    t.add_column("benchmark")
    t.add_column("result", justify="right")
    for key in sorted(k for k in res if k.startswith("env_")):
        e = res[key]
        native_t = f" (native code {e['native_threads']})" if e.get("native_threads") else ""
        t.add_row(f"env {e['robot']}, {e['num_envs']} envs, limits {e['limits']}, torch {e['threads']} thread(s)"
                  f"{native_t}",
                  f"{e['env_steps_per_s']:,.0f} steps/s")
    t.add_row("single-env reference iiwa7", f"{res['reference_iiwa7']['env_steps_per_s']:,.0f} steps/s")
    t.add_row("batched / reference (iiwa7)", f"{res['batched_over_reference_iiwa7']:,.0f} x")
    if res["ppo_iteration_iiwa7"]["hidden_dtype"] == "float32":  # main() found bfloat16 emulated
        t.add_row("bfloat16 hidden layers: emulated on this CPU, not timed",
                  f"{res['bfloat16_over_float32_layer']:.0f} x float32")
    for key in sorted(k for k in res if k.startswith("ppo_iteration_")):
        p = res[key]
        share = ", ".join(f"{k} {100 * v:.0f} %" for k, v in p["share"].items())
        t.add_row(f"PPO iteration {p['robot']} ({p['num_envs']} envs x {p['steps_per_env']} steps), hidden "
                  f"{p['hidden_dtype']}, {p['threads']} thread(s): {share}",
                  f"{p['s_per_iteration']:.2f} s, {p['samples_per_s']:,.0f} samples/s")
    for k in ("ball_task_analytic", "ball_task_pybullet"):
        b = res[k]
        t.add_row(f"ball task, {b['backend']}, {b['num_envs']} envs", f"{b['env_steps_per_s']:,.0f} steps/s")
    t.add_row("ball task analytic / PyBullet", f"{res['ball_task_analytic_over_pybullet']:,.0f} x")
    t.add_row("kinematic tracking env (2 cores) / PyBullet ball env (2 workers)",
              f"{res['kinematic_tracking_over_pybullet_ball']:,.0f} x")
    t.add_row("kinematic tracking env (1 thread) / PyBullet ball env (2 workers)",
              f"{res['kinematic_tracking_1thread_over_pybullet_ball']:,.0f} x")
    for k in sorted(k for k in res if k.startswith("decision_")):
        d = res[k]
        t.add_row(f"policy + limits per decision, {d['robot']}, limits {d['limits']}",
                  f"{d['mean_ms']:.2f} ms (max {d['max_pct_of_step']:.1f} % of 0.1 s)")
    _follower_rows(t, res)
    d = res["trueadapt_decision"]
    t.add_row(f"TrueAdapt decision (policy + valid range + setpoints), {Path(d['model']).name}, 1 thread",
              f"{d['decision_ms_mean']:.2f} ms mean (max {d['decision_ms_max']:.2f}; valid range max "
              f"{d['valid_range_ms_max']:.2f})")
    for k in ("physics_ball_on_plate", "physics_armar4_standing"):
        d = res[k]
        t.add_row(f"PyBullet {d['scene']} (one client)", f"{d['physics_steps_per_s']:,.0f} physics steps/s "
                  f"({d['decisions_per_s']:,.1f} decisions/s)")
    Console().print(t)


if __name__ == "__main__":
    main()
