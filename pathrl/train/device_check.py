"""The device checks of a run, as functions: ``tests/test_device.py`` calls them on every device this machine has,
and ``tools/gpu_check.py`` on a GPU machine from a bare copy of the package (no ``tests/``, no committed data).

Each takes a shipped model directory (its ``config.yaml`` is the run config, its ``model.pt`` the policy) and a dataset
directory (``train`` and ``test`` splits of the model's robot):

- :func:`step_parity`: the model's env on the CPU (native limit code) and on another device (torch limit code), the
  same start states, the same actions: the largest differences of state, observation, reward and action per step;
- :func:`train_resume_evaluate`: a tiny run on a device, uninterrupted and killed-then-resumed, the two final weights
  compared, every tensor of the resumed run on the run's device, then evaluated on the evaluation device;
- :func:`env_steps_per_s`, :func:`ppo_iteration`: the speed of plain path tracking on a device.

No Hydra: the configs are the model's, the PPO agent is ``conf/agent/ppo.yaml``.
"""

from __future__ import annotations

import contextlib
import copy
import io
import time
from pathlib import Path
from typing import Any

import torch
import yaml

from pathrl.config.migrate import NO_TASK, migrate
from pathrl.config.paths import CONF_DIR
from pathrl.envs.registry import EnvRequest, make_env
from pathrl.envs.state import restore, snapshot, unwrapped
from pathrl.limits.backend import LimitBackend
from pathrl.storage import load_checkpoint

__all__ = ["CHECKED_TASKS", "PARITY_TOL", "available_devices", "env_steps_per_s", "model_cfg", "ppo_iteration",
           "refusals", "step_parity", "sync", "tiny_run_cfg", "tracking_cfg", "train_resume_evaluate",
           "walker_finds_misplaced"]

#: Largest difference allowed between two devices: float64 states, observations and rewards, float32 actions.
PARITY_TOL = {"state": 1e-6, "obs": 1e-5, "reward": 1e-5, "action": 1e-4}


def available_devices() -> list[str]:
    """``cpu``, and ``cuda`` where this torch sees a CUDA device."""
    return ["cpu", *(["cuda"] if torch.cuda.is_available() else [])]


def sync(device: torch.device | str) -> None:
    """Wait for the device's queued work (CUDA); nothing on the CPU."""
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


#: The tasks whose models the checks take: path tracking, without or with the ball on the plate (whose analytic
#: model draws nothing while it steps, so two devices step alike from the same state).
CHECKED_TASKS = ("tracking", "ball_on_plate")


def model_cfg(model: Path) -> tuple[dict[str, Any], Path]:
    """(run config in the current layout, checkpoint) of a shipped model or run directory; ValueError (one line) for a
    controller's directory or a task outside :data:`CHECKED_TASKS`."""
    from pathrl.runs import load_run

    cfg, ckpt, _ = load_run(Path(model))
    if ckpt is None:
        raise ValueError(f"{model}: a model-based controller; the device checks need a trained policy")
    task = (cfg.get("task") or {}).get("name", "tracking")
    if task not in CHECKED_TASKS:
        raise ValueError(f"{model}: task {task}; the device checks take a policy of task {' or '.join(CHECKED_TASKS)}")
    return cfg, ckpt


def tiny_run_cfg(model: Path, dataset: Path, device: str, run_dir: Path, iterations: int, num_envs: int = 32,
                 steps_per_env: int = 8) -> dict[str, Any]:
    """The model's run config as a tiny run on `device`: `num_envs` envs x `steps_per_env` steps, a checkpoint every
    iteration, one thread, eager limit kernels, no warm start or bias search, the ball analytic (PyBullet: CPU only)."""
    cfg = copy.deepcopy(model_cfg(model)[0])
    cfg.update(device=device, threads=1, compile_limits=False, iterations=int(iterations), resume=False, seed=0,
               run_dir=str(run_dir), experiment=f"device_check_{Path(model).name}", init_from=None, bias_search={})
    cfg["dataset"]["path"] = str(dataset)
    cfg["env"]["num_envs"] = int(num_envs)
    cfg["agent"].update(num_steps_per_env=int(steps_per_env), save_interval=1)
    if (cfg.get("task") or {}).get("backend") == "pybullet":
        cfg["task"]["backend"] = "analytic"  # PyBullet trains on the CPU only
    return cfg


def refusals() -> dict[str, Any]:
    """The one-line refusal of each bad device setting (a misspelt name, a CUDA index beyond the devices, CUDA where
    there is none, a PyBullet task off the CPU) and ``ok``: each refused, in one line."""
    from pathrl.envs.device import DeviceError, check_run_device

    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    cases = {"misspelt": {"device": "cdua"}, "index beyond the devices": {"device": f"cuda:{max(count, 7)}"},
             "pybullet task on a gpu": {"device": "cuda", "task": {"name": "ball_on_plate",
                                                                   "feedback": "ball_on_plate", "backend": "pybullet"}}}
    if count == 0:
        cases["cuda without cuda"] = {"device": "cuda"}
    lines: dict[str, str | None] = {}
    for name, cfg in cases.items():
        try:
            check_run_device(cfg)
            lines[name] = None
        except DeviceError as exc:
            lines[name] = str(exc)
    return {"lines": lines, "ok": all(v is not None and "\n" not in v for v in lines.values())}


def walker_finds_misplaced(model: Path, dataset: Path, device: str = "cpu") -> dict[str, Any]:
    """The model's env on `device` walked for tensors off it (none), then again with three tensors moved to the
    ``meta`` device: a state tensor, a dict entry (the episode rewards) and one of the ball's; ``ok``: exactly these
    found."""
    from pathrl.envs.device import off_device

    cfg, _ = model_cfg(model)
    backend = "analytic" if (cfg.get("task") or {}).get("feedback") == "ball_on_plate" else None
    env = make_env(cfg, EnvRequest(num_envs=4, seed=0, dataset_path=str(dataset), backend=backend), device=device)
    before = off_device(env, device)
    env.pos = env.pos.to("meta")
    term = next(iter(env.ep_reward))
    env.ep_reward[term] = env.ep_reward[term].to("meta")
    expected = ["env.pos (meta)", f"env.ep_reward[{term!r}] (meta)"]
    if env.feedback is not None and isinstance(getattr(env.feedback, "xy", None), torch.Tensor):
        env.feedback.xy = env.feedback.xy.to("meta")
        expected.append("env.feedback.xy (meta)")
    found = off_device(env, device)
    return {"before": before, "found": found, "ok": not before and found == sorted(expected)}


def _eval_overrides(device: str, native_code: bool) -> dict[str, Any]:
    """Env settings of a parity env: no auto-reset (no new random draws), `device`, its limit code."""
    return {"autoreset": False, "device": device, "limit_backend": LimitBackend(native=native_code)}


def _without_generators(state: dict[str, Any]) -> dict[str, Any]:
    """A :func:`~pathrl.envs.state.snapshot` without generator states (a CPU generator's state does not fit a CUDA
    one; the parity envs draw nothing while they step)."""
    out = {}
    for k, v in state.items():
        if isinstance(v, dict) and "__generator__" in v:
            continue
        out[k] = {"__part__": _without_generators(v["__part__"])} if isinstance(v, dict) and "__part__" in v else v
    return out


def step_parity(model: Path, dataset: Path, other: str, num_envs: int = 64, steps: int = 20) -> dict[str, Any]:
    """The model's env (its task; a PyBullet ball as the analytic one) on the CPU with the native limit code and on
    `other` with the torch code, from the same start states (the CPU env's copied over), stepped with the CPU
    policy's actions; the largest absolute differences over all steps (``max_abs``) and ``ok`` (within
    :data:`PARITY_TOL`). ``action``: the policy on `other` against the CPU policy on the same observations."""
    from pathrl.runs import load_policy

    cfg, ckpt = model_cfg(model)
    backend = "analytic" if (cfg.get("task") or {}).get("feedback") == "ball_on_plate" else None
    request = EnvRequest(num_envs=num_envs, seed=0, dataset_path=str(dataset), backend=backend)
    envs = [make_env(cfg, request, **_eval_overrides(dev, dev == "cpu" and native_code))
            for dev, native_code in (("cpu", True), (other, False))]
    ref, oth = envs
    restore(unwrapped(oth), _without_generators(snapshot(unwrapped(ref))))
    pol_ref, pol_oth = (load_policy(cfg, e, ckpt) for e in envs)
    worst = {k: 0.0 for k in ("pos", "vel", "acc", "s", "obs", "reward", "action")}
    dones_equal = True

    def diff(key: str, a: torch.Tensor, b: torch.Tensor) -> None:
        worst[key] = max(worst[key], float((a.double() - b.to(a.device).double()).abs().max()))

    for _ in range(steps):
        obs_ref, obs_oth = ref.get_observations(), oth.get_observations()
        with torch.inference_mode():
            act = pol_ref(obs_ref)
            diff("action", act, pol_oth(obs_oth))
        diff("obs", obs_ref["policy"], obs_oth["policy"])
        _, r_ref, d_ref, _ = ref.step(act)
        _, r_oth, d_oth, _ = oth.step(act.to(oth.device))
        diff("reward", r_ref, r_oth)
        dones_equal &= bool(torch.equal(d_ref, d_oth.cpu()))
        for key in ("pos", "vel", "acc", "s"):
            diff(key, getattr(ref, key), getattr(oth, key))
    tol = {k: PARITY_TOL["state" if k in ("pos", "vel", "acc", "s") else k] for k in worst}
    ok = dones_equal and all(worst[k] <= tol[k] for k in worst)
    return {"devices": ["cpu", other], "limits": ["native", "torch"], "num_envs": num_envs, "steps": steps,
            "task": cfg["task"]["name"], "max_abs": worst, "tolerance": tol, "dones_equal": dones_equal, "ok": ok}


def _weights(path: Path) -> dict[str, torch.Tensor]:
    """Every network tensor of a checkpoint (``<model>_state_dict`` entries), by dotted name."""
    state = load_checkpoint(path)
    return {f"{k}.{n}": t for k, v in state.items() if k.endswith("_state_dict") and k != "optimizer_state_dict"
            for n, t in v.items() if isinstance(t, torch.Tensor)}


def train_resume_evaluate(model: Path, dataset: Path, device: str, work: Path, num_envs: int = 32,
                          steps_per_env: int = 8, episodes: int = 4) -> dict[str, Any]:
    """A tiny run of the model's config on `device`: 3 iterations uninterrupted (``a``), and 2 then resumed to 3
    (``b``); the largest difference of their final weights (0 on the CPU: a resume is exact there), the tensors of
    the resumed run not on `device` (none expected), and `episodes` evaluation episodes of ``b`` on the evaluation
    device (its config says `device`)."""
    from pathrl.eval.evaluate import EvalOptions, evaluate
    from pathrl.train.placement import stray_tensors
    from pathrl.train.runner import train

    t0, work, stray = time.perf_counter(), Path(work), []

    def cfg(name: str, iterations: int) -> dict[str, Any]:
        return tiny_run_cfg(model, dataset, device, work / name, iterations, num_envs, steps_per_env)

    with contextlib.redirect_stdout(io.StringIO()):  # rsl-rl's per-iteration printout
        train(cfg("a", 3), work / "a")
        train(cfg("b", 2), work / "b")
        train(cfg("b", 3), work / "b", resume=True, on_start=lambda runner: stray.extend(stray_tensors(runner)))
    wa, wb = _weights(work / "a" / "model_2.pt"), _weights(work / "b" / "model_2.pt")
    weight_diff = max(float((wa[k] - wb[k]).abs().max()) for k in wa)
    threads = torch.get_num_threads()
    try:
        opts = EvalOptions(dataset_path=str(dataset), episodes=episodes, segments="full", out_dir=work / "eval",
                           num_envs=episodes, record=False, progress=False, backend="analytic")
        metrics = evaluate(work / "b", opts)
    finally:
        torch.set_num_threads(threads)  # evaluate() sets its own (PATHRL_THREADS)
    saved_device = yaml.safe_load((work / "b" / "config.yaml").read_text())["device"]
    exact = torch.device(device).type == "cpu"
    ok = not stray and metrics["episodes"] == episodes and (weight_diff == 0.0 if exact else weight_diff < 1e-2)
    return {"device": device, "iterations": 3, "resumed_at": 2, "num_envs": num_envs, "weights": len(wa),
            "resume_max_weight_diff": weight_diff, "bit_exact": weight_diff == 0.0, "off_device": stray,
            "saved_device": saved_device, "eval_episodes": metrics["episodes"],
            "eval_limit_violations": metrics["limit_violations"], "eval_duration_s": metrics["duration_s"],
            "ok": ok, "seconds": round(time.perf_counter() - t0, 2)}


def tracking_cfg(model: Path, dataset: Path, device: str) -> dict[str, Any]:
    """Plain path tracking on the model's robot, knots and env settings (no task, ``conf/reward/balanced.yaml``,
    ``conf/agent/ppo.yaml``), on `device` and `dataset`: what ``make bench`` measures."""
    cfg = copy.deepcopy(model_cfg(model)[0])
    cfg["task"] = dict(NO_TASK)
    cfg["reward"] = yaml.safe_load((CONF_DIR / "reward" / "balanced.yaml").read_text())
    cfg["agent"] = yaml.safe_load((CONF_DIR / "agent" / "ppo.yaml").read_text())
    cfg["dataset"]["path"] = str(dataset)
    cfg.update(device=device, residual={}, teacher={}, compile_limits=False)
    cfg["env"].update(segments="paper", max_deviation=cfg["env"].get("max_deviation") or 0.25)
    return migrate(cfg)


def env_steps_per_s(cfg: dict[str, Any], num_envs: int, seconds: float = 3.0, warmup: int = 3,
                    min_steps: int = 2) -> dict[str, Any]:
    """Env steps per second of the run config `cfg`'s env with `num_envs` envs on its device, random actions (8
    cycled batches), after `warmup` untimed steps: at least `min_steps` steps and `seconds` of stepping. The limit
    code: native on the CPU (where built), torch elsewhere."""
    from pathrl import native

    device = torch.device(cfg["device"])
    env = make_env(cfg, EnvRequest(num_envs=num_envs, seed=0))
    gen = torch.Generator(device=device).manual_seed(0)
    actions = [torch.rand(num_envs, env.num_actions, generator=gen, device=device) * 2 - 1 for _ in range(8)]
    for k in range(warmup):
        env.step(actions[k % 8])
    sync(device)
    steps, t0 = 0, time.perf_counter()
    while steps < min_steps or time.perf_counter() - t0 < seconds:
        env.step(actions[steps % 8])
        steps += 1
        if steps % 8 == 0:
            sync(device)
    sync(device)
    dt = time.perf_counter() - t0
    limits = "native" if device.type == "cpu" and native.available() else "torch"
    return {"device": str(device), "num_envs": num_envs, "limits": limits, "threads": torch.get_num_threads(),
            "steps": steps, "seconds": round(dt, 3), "env_steps_per_s": steps * num_envs / dt}


def ppo_iteration(cfg: dict[str, Any], num_envs: int, hidden_dtype: str, iterations: int = 1) -> dict[str, Any]:
    """Seconds per PPO iteration (rollout of ``num_steps_per_env`` steps + update) of `cfg`'s env and agent with
    `num_envs` envs on its device, the models' hidden layers in `hidden_dtype`; after one untimed iteration."""
    from rsl_rl.runners import OnPolicyRunner

    device = str(cfg["device"])
    agent = copy.deepcopy(cfg["agent"])
    for role in ("actor", "critic"):
        agent[role]["hidden_dtype"] = hidden_dtype
    env = make_env(cfg, EnvRequest(num_envs=num_envs, seed=0))
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(env, agent, log_dir=None, device=device)
        runner.learn(1)
        sync(device)
        t0 = time.perf_counter()
        runner.learn(iterations)
        sync(device)
    dt = (time.perf_counter() - t0) / iterations
    samples = int(agent["num_steps_per_env"]) * num_envs
    return {"device": device, "num_envs": num_envs, "steps_per_env": int(agent["num_steps_per_env"]),
            "hidden_dtype": hidden_dtype, "threads": torch.get_num_threads(), "iterations": iterations,
            "s_per_iteration": dt, "samples_per_s": samples / dt}
