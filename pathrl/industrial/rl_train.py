"""Training loop of the waypoint-adjustment policy (paper Alg. 3), resumable, logged to MCAP.

Training set: ``n_train`` random type-1 trajectories (:func:`pathrl.industrial.trajectories.type1_random`,
seeds ``1000 * (seed + 1) + i``) in the three poses (pose 1 + i mod 3) at the poses' speed commands (250, 400,
400 mm/s, as in the evaluation). Each iteration: actions for all m waypoints (random during ``warmup``, then
the policy plus Gaussian noise ``expl_noise``, correlated along the path over ``expl_smooth`` waypoints
if > 0), one execution, m transitions into the prioritized buffer,
``updates_per_iter`` TD3 updates; a global termination starts a new episode on a random training trajectory.

Run directory: ``model_<K>.pt`` checkpoints (pathrl.storage: atomic, digest-verified, weights only) every
``checkpoint_every`` iterations and at the end, holding the networks, optimizers, iteration and RNG states;
``train_<start>.mcap`` per (re)start with ``/run/config`` and ``/train/scalars``. ``resume`` continues from the
newest valid checkpoint; the replay buffer is not checkpointed (it refills from the resumed policy).
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from pathrl.industrial.controller import ControllerParams
from pathrl.industrial.features import N_FEATURES
from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
from pathrl.industrial.per import PrioritizedBuffer
from pathrl.industrial.rl import N_ACTIONS, RLParams, TD3Agent
from pathrl.industrial.trajectories import Target, type1, type1_random
from pathrl.logging.mcap_io import McapJsonWriter
from pathrl.logging.schema import RUN_CONFIG, TRAIN_SCALARS
from pathrl.storage import clean_leftovers, latest_valid_checkpoint, load_checkpoint, save_checkpoint

__all__ = ["ACTOR_PREFIX", "POSE_SPEEDS", "actor_stats", "load_agent", "path_noise", "ship_policy", "train",
           "training_target"]

#: Speed command (mm/s) of the training trajectories per pose.
POSE_SPEEDS = {1: 250.0, 2: 400.0, 3: 400.0}


def training_target(i: int, seed: int = 0) -> Target:
    """Training trajectory i of the family (module doc)."""
    pose = 1 + i % 3
    p, rot = type1(type1_random(1000 * (seed + 1) + i), pose)
    return Target(f"train{i}", p, rot, pose, "L", POSE_SPEEDS[pose])


#: Prefix of the actor's weights in the TD3 loss module's state dict (all a shipped policy keeps).
ACTOR_PREFIX = "actor_network_params."


def ship_policy(run_dir: Path, dest: Path) -> Path:
    """Write the actor of the newest valid checkpoint of `run_dir` (weights, RL settings, iteration; no critics,
    targets or optimizers) to ``dest/model.pt``; :func:`load_agent` reads it for evaluation."""
    ckpt = latest_valid_checkpoint(Path(run_dir))
    if ckpt is None:
        raise ValueError(f"{run_dir}: no valid model_<K>.pt checkpoint")
    state = load_checkpoint(ckpt)
    actor = {k: v for k, v in state["agent"]["loss"].items() if k.startswith(ACTOR_PREFIX)}
    Path(dest).mkdir(parents=True, exist_ok=True)
    save_checkpoint({"params": state["params"], "iteration": state["iteration"], "actor": actor,
                     "shipped_from": f"{run_dir}/{ckpt.name}"}, Path(dest) / "model.pt")
    return Path(dest) / "model.pt"


def load_agent(run_dir: Path, params: RLParams | None = None) -> tuple[TD3Agent, int]:
    """The agent of a shipped policy (``model.pt``, actor only: for acting) or of the newest valid training
    checkpoint in `run_dir`, and its iteration (ValueError if there is none)."""
    shipped = Path(run_dir) / "model.pt"
    ckpt = shipped if shipped.is_file() else latest_valid_checkpoint(Path(run_dir))
    if ckpt is None:
        raise ValueError(f"{run_dir}: no model.pt and no valid model_<K>.pt checkpoint")
    state = load_checkpoint(ckpt)
    params = RLParams(**state["params"]) if params is None else params
    agent = TD3Agent(params)
    if "actor" in state:
        missing = agent.loss.load_state_dict(state["actor"], strict=False).missing_keys
        if any(k.startswith(ACTOR_PREFIX) for k in missing):
            raise ValueError(f"{ckpt}: the shipped actor does not fit the RL settings")
    else:
        agent.load_state_dict(state["agent"])
    return agent, int(state["iteration"])


def path_noise(rng: np.random.Generator, m: int, std: float, smooth: float) -> np.ndarray:
    """Gaussian noise (m, 3) with std `std` at every waypoint, correlated along the path with a Gaussian of width
    `smooth` waypoints (each waypoint's noise is a unit-norm weighted sum of white noise; 0 = independent)."""
    white = rng.normal(0.0, std, (m, N_ACTIONS))
    if smooth <= 0.0:
        return white
    idx = np.arange(m)
    w = np.exp(-0.5 * ((idx[:, None] - idx[None, :]) / smooth) ** 2)
    return (w / np.linalg.norm(w, axis=1, keepdims=True)) @ white


def _explore(agent: TD3Agent, obs: np.ndarray, it: int, params: RLParams,
             rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(exploration actions (m, 3) in [-1, 1], the deterministic actor's (m, 3); zeros during warm-up)."""
    if it < params.warmup:
        return rng.uniform(-1.0, 1.0, (len(obs), N_ACTIONS)), np.zeros((len(obs), N_ACTIONS))
    mean = agent.act(obs)
    return np.clip(mean + path_noise(rng, len(obs), params.expl_noise, params.expl_smooth), -1.0, 1.0), mean


def actor_stats(mean: np.ndarray, clip: float) -> dict[str, float]:
    """Mean actions a1-a3 (in action units: `clip` x the tanh output) and the share of tanh outputs beyond 0.95
    (at the clip) of the deterministic actor's actions `mean` (m, 3)."""
    out = {f"a{j + 1}": float(clip * mean[:, j].mean()) for j in range(N_ACTIONS)}
    out["at_clip"] = float((np.abs(mean) > 0.95).mean())
    return out


def train(run_dir: Path, params: RLParams, controller: ControllerParams, m: int = 100, zone: float = 10.0,
          resume: bool = False, config: dict[str, Any] | None = None, progress: bool = False) -> dict[str, Any]:
    """Train (or resume) a policy into `run_dir`; returns a summary (iterations, episodes, wall time)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    clean_leftovers(run_dir)
    agent = TD3Agent(params)
    tgen = torch.Generator().manual_seed(params.seed)
    buffer = PrioritizedBuffer(params.buffer, N_FEATURES, N_ACTIONS, params.per_alpha, params.per_beta, generator=tgen)
    rng = np.random.default_rng(params.seed)
    start = 0
    ckpt = latest_valid_checkpoint(run_dir) if resume else None
    if ckpt is not None:
        state = load_checkpoint(ckpt)
        agent.load_state_dict(state["agent"])
        start = int(state["iteration"])
        rng.bit_generator.state = state["np_rng"]
    t0 = time.perf_counter()
    keys = ("reward", "err", "loss_q", "loss_actor", "a1", "a2", "a3", "at_clip")
    log: dict[str, list[float]] = {k: [] for k in keys}
    episodes, env, obs = 0, None, None
    with McapJsonWriter(run_dir / f"train_{start:06d}.mcap") as writer:
        writer.write(RUN_CONFIG, {"config": config or {}, "params": asdict(params), "resumed_from": start})
        for it in range(start, params.iterations):
            if env is None:
                target = training_target(int(rng.integers(params.n_train)), params.seed)
                settings = IWASettings(m, zone, params.k_max, 2.0, params.w_ori, params.success_decay)
                env = IWAEpisode(target, target.speed, controller, settings)
                obs, episodes = env.reset(), episodes + 1
            action, mean = _explore(agent, obs, it, params, rng)
            if it >= params.warmup:
                for k, v in actor_stats(mean, params.action_clip).items():
                    log[k].append(v)
            res = env.step(params.action_clip * action)
            buffer.add(torch.as_tensor(obs), torch.as_tensor(action), torch.as_tensor(res.reward),
                       torch.as_tensor(res.obs), torch.as_tensor(res.done))
            log["reward"].append(float(res.reward.mean()))
            log["err"].append(res.errors.max_pos_mm if res.errors is not None else float("nan"))
            obs, env = res.obs, (None if res.terminal else env)
            if len(buffer) >= params.batch:
                for _ in range(params.updates_per_iter):
                    for k, v in agent.update(buffer).items():
                        log[k].append(v)
            if (it + 1) % params.log_every == 0 or it + 1 == params.iterations:
                scalars = {k: float(np.nanmean(v)) for k, v in log.items() if v}
                scalars.update(episodes=episodes, buffer=len(buffer), wall_s=time.perf_counter() - t0)
                writer.write(TRAIN_SCALARS, {"iteration": it + 1, "values": scalars})
                writer.flush()
                if progress:
                    print(f"it {it + 1}: " + " ".join(f"{k}={v:.3g}" for k, v in scalars.items()), flush=True)
                log = {k: [] for k in log}
            if (it + 1) % params.checkpoint_every == 0 or it + 1 == params.iterations:
                save_checkpoint({"agent": agent.state_dict(), "iteration": it + 1, "np_rng": rng.bit_generator.state,
                                 "params": asdict(params)}, run_dir / f"model_{it + 1}.pt")
    return {"iterations": params.iterations, "started_at": start, "episodes": episodes,
            "wall_s": time.perf_counter() - t0}
