"""Build a run from a resolved config: dataset -> env -> RSL-RL OnPolicyRunner; train with checkpoints and resume.

The run reads its config as the typed :class:`pathrl.schema.TrainAppCfg` (the CLI converts once; a mapping given
here is checked and converted by :func:`check_run_cfg`); the library code that also reads saved runs (the env
registry, resume, bias search) takes its plain dict (:func:`pathrl.schema.config_dict`), which is what
``config.yaml`` holds."""

from __future__ import annotations

import copy
import json
import math
import shutil
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import torch
import yaml
from rsl_rl.runners import DistillationRunner, OnPolicyRunner

from pathrl.envs.device import check_run_device
from pathrl.envs.path_changes import PathChanges
from pathrl.envs.registry import make_env
from pathrl.envs.state import restore, snapshot, snapshot_is_exact, unwrapped
from pathrl.envs.tracking import PathTrackingEnv
from pathrl.limits.backend import LimitBackend
from pathrl.policy import policy_role
from pathrl.policy.models import MixedMLP
from pathrl.policy.residual import ControllerObs, ResidualEnv, check_residual_cfg, zero_last_layer
from pathrl.schema import TrainAppCfg, config_dict, train_app_cfg
from pathrl.storage import (
    atomic_write,
    checkpoint_iteration,
    latest_checkpoint,
    load_checkpoint,
    save_checkpoint,
    write_json_atomic,
)
from pathrl.train.curricula import apply_ball_curriculum, apply_reward_curriculum
from pathrl.train.placement import placement_warning, resume_notes, start_notes
from pathrl.train.resume import RESUME_MAY_CHANGE, config_change, finished_summary, resume_checkpoint, resume_point

__all__ = [
    "PathRLDistillationRunner", "PathRLRunner", "RESUME_MAY_CHANGE", "check_run_cfg", "config_change",
    "float32_iteration", "resume_point", "log_linear", "rsl_train_cfg", "train",
]


def rsl_train_cfg(cfg: TrainAppCfg, resume_from: int | None = None) -> dict[str, Any]:
    """RSL-RL train cfg: the agent config verbatim plus our MCAP log writer (given the run config as a plain dict),
    which keeps the log up to the checkpoint iteration `resume_from` (None: a fresh log)."""
    agent = copy.deepcopy(cfg.agent)
    agent["logger"] = {"class_name": "pathrl.train.mcap_logger:McapLogWriter", "run_config": config_dict(cfg),
                       "keep_through": resume_from}
    return agent


def log_linear(it: int, total: int, initial: float, final: float, start: float) -> float:
    """A schedule's value at iteration `it` of `total` (the action-noise cap, the learning rate): `initial` until
    `start * total`, then log-linear down to `final` at the last iteration."""
    t0 = start * total
    frac = min(max((it - t0) / max(total - 1 - t0, 1.0), 0.0), 1.0)
    return float(initial * (final / initial) ** frac)


class PathRLRunner(OnPolicyRunner):
    """OnPolicyRunner with atomic checkpoints, safe (weights-only) loading and an optional action-noise cap.

    PPO evaluates the policy's mean action, but trains it under noise; near the path end a noisy policy
    can let the noise do the last centimetres. Capping the std late in training (``std_anneal``) makes
    the mean action itself finish the path.
    """

    def after_each_update(self, fn: Callable[[int], None]) -> None:
        """Call ``fn(it)`` after every update, `it` being the iteration that starts next (counted from the
        run's current iteration, so a resumed run continues the count)."""
        update, next_it = self.alg.update, [self.current_learning_iteration]

        def update_then_call() -> dict[str, float]:
            out = update()
            next_it[0] += 1
            fn(next_it[0])
            return out

        self.alg.update = update_then_call

    def before_each_update(self, fn: Callable[[int], None]) -> None:
        """Call ``fn(it)`` right before the update of iteration `it` (so the logs of that iteration show its effect)."""
        update, it = self.alg.update, [self.current_learning_iteration]

        def call_then_update() -> dict[str, float]:
            fn(it[0])
            it[0] += 1
            return update()

        self.alg.update = call_then_update

    def set_std_schedule(self, total: int, init_std: float, final: float, start: float) -> None:
        """Cap the std before every rollout (the cap depends only on the iteration, so resume reproduces it)."""
        dist = self.alg.get_policy().distribution

        def apply(it: int) -> None:
            dist.std_range[1] = max(log_linear(it, total, init_std, final, start), dist.std_range[0])
            dist.log_std_range[1] = math.log(dist.std_range[1])

        apply(self.current_learning_iteration)
        self.after_each_update(apply)

    def set_lr_decay(self, total: int, final: float, start: float) -> None:
        """Set the learning rate of every update from :func:`log_linear` (from the configured rate to `final`; it
        depends only on the iteration, so a resume reproduces it). PPO or Distillation alike."""
        alg, lr0 = self.alg, float(self.alg.learning_rate)

        def apply(it: int) -> None:
            alg.learning_rate = log_linear(it, total, lr0, final, start)
            for group in alg.optimizer.param_groups:
                group["lr"] = alg.learning_rate

        self.before_each_update(apply)

    def set_float32_from(self, iteration: int) -> None:
        """From iteration `iteration` on (counted from 0, so a resume continues the count) the hidden layers of a
        bfloat16 actor and critic (:class:`~pathrl.policy.models.MixedPrecisionMLPModel`) compute in float32: the
        fast precision while the policy explores, the exact one while the action noise is annealed."""
        models = (getattr(self.alg, "actor", None), getattr(self.alg, "critic", None))
        mlps = [m.mlp for m in models if isinstance(getattr(m, "mlp", None), MixedMLP)]

        def apply(it: int) -> None:
            if it >= iteration:
                for mlp in mlps:
                    mlp.dtype = torch.float32

        apply(self.current_learning_iteration)
        self.after_each_update(apply)

    def freeze_actor_normalizer(self) -> bool:
        """Keep the actor's observation normaliser as it is now (until ``del actor.update_normalization``); False
        when it was frozen already, so that only the caller that froze it thaws it."""
        actor = self.alg.get_policy()
        if "update_normalization" in vars(actor):
            return False
        actor.update_normalization = lambda obs: None  # instance attribute shadows the method
        return True

    def set_critic_warmup(self, iterations: int, learning_rate: float | None = None) -> None:
        """For the first `iterations` iterations of the run (counted from 0, so a resume continues the count)
        only the critic learns: the actor's weights, action std and observation normalizer stay as loaded.
        A warm start with a new critic (e.g. from a distilled student) would otherwise follow the advantages
        of an untrained value function. The actor then starts at `learning_rate` (default: the configured one;
        the adaptive schedule sees no KL while the actor is frozen, and reacts only after a first update at
        this rate)."""
        if self.current_learning_iteration >= iterations:
            return
        actor = self.alg.get_policy()
        lr0 = float(self.alg.learning_rate if learning_rate is None else learning_rate)
        for p in actor.parameters():
            p.requires_grad_(False)
        thaw = self.freeze_actor_normalizer()  # False: frozen for the whole run (critic_warmup.freeze_normalizer)

        def release(it: int) -> None:
            if it != iterations:
                return
            for p in actor.parameters():
                p.requires_grad_(True)
            if thaw:
                del actor.update_normalization
            self.alg.learning_rate = lr0
            for group in self.alg.optimizer.param_groups:
                group["lr"] = lr0

        self.after_each_update(release)

    _summary: Path | None = None
    _wall: tuple[float, float] = (0.0, 0.0)

    def track_wall_time(self, summary: Path, before_s: float) -> None:
        """From now on every checkpoint also records the training wall time so far (`before_s` plus the time
        since this call) in `summary`, so a run killed between sessions still accounts for its time."""
        self._summary, self._wall = summary, (before_s, time.perf_counter())

    def wall_time_s(self) -> float:
        """Training wall time so far (s), including the runs before a resume (see `track_wall_time`)."""
        return self._wall[0] + time.perf_counter() - self._wall[1]

    def save(self, path: str, infos: dict | None = None) -> None:
        """Checkpoint with a content digest (:mod:`pathrl.storage.checkpoints`), written atomically, holding what a
        resume needs to continue exactly: weights, optimizer, iteration, the torch RNG and the env's state."""
        if self.logger.writer is not None:
            self.logger.writer.flush()  # the checkpoint's iteration is in run.mcap before the checkpoint exists
        if self._summary is not None:
            prev = json.loads(self._summary.read_text()) if self._summary.exists() else {}
            write_json_atomic(self._summary, {**prev, "wall_time_s": self.wall_time_s()})
        saved = self.alg.save()
        saved["iter"] = self.current_learning_iteration
        # The wall time in the checkpoint itself: time-to-quality curves read it (pathrl.eval.curve).
        saved["infos"] = {**(infos or {}), **({"wall_time_s": self.wall_time_s()} if self._summary else {})}
        saved["rng_torch"] = torch.get_rng_state()
        if torch.device(self.device).type == "cuda":  # the action noise of a CUDA run is drawn there
            saved["rng_cuda"] = torch.cuda.get_rng_state(self.device)
        saved["env_state"] = snapshot(unwrapped(self.env))
        saved["env_state_exact"] = snapshot_is_exact(self.env)
        if isinstance(self.env, ControllerObs):  # a teacher's or a residual's controller has a plan in progress
            saved["controller_state"] = self.env.state_dict()
        save_checkpoint(saved, Path(path))
        self.logger.save_model(path, self.current_learning_iteration)

    def load(self, path: str, load_cfg: dict | None = None, strict: bool = True,
             map_location: str | None = "cpu") -> dict:
        """Load the verified checkpoint at `path` (weights only) into the runner; see :meth:`load_state`. It loads
        to the CPU by default, so a GPU run's checkpoint loads without CUDA (the weights go to the runner's device)."""
        return self.load_state(load_checkpoint(Path(path), map_location=map_location), load_cfg, strict)

    def load_state(self, loaded: dict, load_cfg: dict | None = None, strict: bool = True) -> dict:
        """Weights (and optimizer, iteration) of a loaded checkpoint; see :meth:`restore_streams` for the rest."""
        if self.alg.load(loaded, load_cfg, strict):
            self.current_learning_iteration = int(loaded["iter"])
        return loaded.get("infos") or {}

    def restore_streams(self, loaded: dict) -> bool:
        """The torch RNGs (CPU, and CUDA on a CUDA run) and the env's episodes as they were at the checkpoint, every
        tensor on the run's device (checkpoints from before these were stored have neither). Returns whether the
        env's episodes continue exactly."""
        if "env_state" not in loaded:
            return False
        restore(unwrapped(self.env), loaded["env_state"])
        if isinstance(self.env, ControllerObs):
            if "controller_state" not in loaded:
                return False
            self.env.load_state_dict(loaded["controller_state"])
        torch.set_rng_state(loaded["rng_torch"])
        if torch.device(self.device).type == "cuda" and "rng_cuda" in loaded:
            torch.cuda.set_rng_state(loaded["rng_cuda"].cpu(), self.device)
        return bool(loaded.get("env_state_exact", False))


class PathRLDistillationRunner(PathRLRunner, DistillationRunner):
    """rsl-rl's DistillationRunner (student-teacher behaviour cloning) with PathRLRunner's checkpoints."""

    def load_state(self, loaded: dict, load_cfg: dict | None = None, strict: bool = True) -> dict:
        """As :meth:`PathRLRunner.load_state`; by default loads the student, its optimizer and the iteration."""
        # A controller teacher has an empty state dict, which rsl-rl's default (teacher included) takes for a
        # missing one; resume loads the student, its optimizer and the iteration.
        return super().load_state(loaded, load_cfg or {"student": True, "optimizer": True, "iteration": True}, strict)


def check_run_cfg(cfg: TrainAppCfg | Mapping[str, Any]) -> TrainAppCfg:
    """The typed run config, its run-level values checked: one-line ValueError naming the key of a value that would
    run but give a wrong result; the env's own values are checked by :class:`pathrl.envs.tracking_cfg.TrackingEnvCfg`.
    A mapping (a resolved config) has its keys checked against the schema (unknown keys refused) and is converted."""
    from pathrl.config.agent import check_agent
    from pathrl.config.validate import check_keys

    if not isinstance(cfg, TrainAppCfg):
        check_keys(cfg, TrainAppCfg)
        cfg = train_app_cfg(cfg)
    if cfg.iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {cfg.iterations}")
    if cfg.threads < 1:
        raise ValueError(f"threads must be >= 1, got {cfg.threads}")
    raw = config_dict(cfg)
    check_run_device(raw)  # cpu, cuda, cuda:N that exists; a PyBullet task on the CPU only (DeviceError)
    if cfg.critic_warmup.iterations < 0:
        raise ValueError(f"critic_warmup.iterations must be >= 0, got {cfg.critic_warmup.iterations}")
    check_agent(cfg.agent)  # RSL-RL's keys: types and ranges (gamma, lambda, learning rate, dims, ...)
    if cfg.float32_from is not None:
        float32_iteration(cfg.float32_from, cfg.iterations)
    _check_lr_decay(cfg)
    LimitBackend.from_run(raw)  # native_limits, compile_limits: true or false
    return cfg


def train(cfg: TrainAppCfg | Mapping[str, Any], run_dir: Path, resume: bool = False,
          on_start: Callable[[PathRLRunner], None] | None = None) -> dict[str, Any]:
    """Train (or resume) a policy; writes config.yaml, checkpoints, run.mcap and summary.json into `run_dir`.
    `cfg`: the typed run config (a resolved mapping is checked and converted once, :func:`check_run_cfg`).
    `on_start(runner)` is called once the runner is built (and, on resume, restored), before the first iteration.

    A start that fails before its first checkpoint leaves `run_dir` as it found it (missing or empty); a resume
    with nothing left to do changes nothing and returns the run's summary."""
    cfg = check_run_cfg(cfg)
    run_dir = Path(run_dir)
    fresh = not run_dir.exists() or (run_dir.is_dir() and not any(run_dir.iterdir()))
    existed = run_dir.exists()
    try:
        return _train(cfg, run_dir, resume, on_start)
    except BaseException:
        if fresh and run_dir.is_dir() and latest_checkpoint(run_dir) is None:
            _undo_start(run_dir, keep_dir=existed)
        raise


def _undo_start(run_dir: Path, keep_dir: bool) -> None:
    """Remove what a failed start wrote into `run_dir` (and the directory itself unless `keep_dir`)."""
    for p in list(run_dir.iterdir()):
        shutil.rmtree(p, ignore_errors=True) if p.is_dir() and not p.is_symlink() else p.unlink(missing_ok=True)
    if not keep_dir:
        run_dir.rmdir()


def _train(cfg: TrainAppCfg, run_dir: Path, resume: bool,
           on_start: Callable[[PathRLRunner], None] | None) -> dict[str, Any]:
    """:func:`train` after its checks."""
    raw = config_dict(cfg)  # what config.yaml holds and the dict-reading library code takes
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    run_dir.mkdir(parents=True, exist_ok=True)
    ckpt = resume_checkpoint(run_dir, raw, resume)
    finished = finished_summary(run_dir, ckpt, cfg.iterations)
    if finished is not None:
        print(f"note: {run_dir} has finished {finished['iterations']} iterations (iterations={cfg.iterations}): "
              "nothing to do, nothing changed", file=sys.stderr)
        return finished
    env = _training_env(cfg, raw)
    atomic_write(run_dir / "config.yaml", yaml.safe_dump(raw, sort_keys=False))
    prev = json.loads((run_dir / "summary.json").read_text()) if (run_dir / "summary.json").exists() else {}
    # The observation normalizer D must be known to evaluate the policy on any other path set.
    write_json_atomic(run_dir / "summary.json", {**prev, "experiment": cfg.experiment, "knot_gap_norm": env.knot_gap})
    rsl = rsl_train_cfg(cfg, None if ckpt is None else checkpoint_iteration(ckpt))  # RSL-RL's train cfg
    distill = _distills(cfg)
    runner_cls = PathRLDistillationRunner if distill else PathRLRunner
    runner = runner_cls(env, rsl, log_dir=str(run_dir), device=cfg.device)
    if distill:
        runner.alg.teacher_loaded = True  # a controller: nothing to load (pathrl.train.distill)
    done_before, loaded = 0, None
    if ckpt is not None:
        loaded = load_checkpoint(ckpt)
        runner.load_state(loaded)
        runner.current_learning_iteration += 1  # the checkpoint's iteration is finished
        done_before = runner.current_learning_iteration
    elif cfg.init_from:
        from pathrl.train.warm_start import warm_start

        warm_start(runner.alg, cfg.init_from, env.num_obs, _init_std(cfg), env.robot.joints, env.robot.path_joints)
    elif cfg.residual:
        zero_last_layer(runner.alg.get_policy())  # the untrained residual policy is its controller
    if ckpt is None and cfg.bias_search:
        from pathrl.train.bias_search import search_before_training

        prev = search_before_training(raw, runner.alg.get_policy(), env.knot_gap, run_dir / "summary.json")
    _schedules(runner, cfg)
    runner.track_wall_time(run_dir / "summary.json", float(prev.get("wall_time_s", 0.0)))
    if loaded is not None:
        resume_notes(runner, loaded, ckpt.name, runner.restore_streams(loaded))
    placement_warning(runner)
    if on_start is not None:
        on_start(runner)
    _learn(runner, cfg, max(cfg.iterations - done_before, 0), raw)
    return _finish(runner, cfg, env, run_dir, int(rsl["num_steps_per_env"]) * env.num_envs)


def _training_env(cfg: TrainAppCfg, raw: dict[str, Any]):
    """The run's training env (its task's, through the registry: bad values and data fail here, before anything is
    written into run_dir), with path changes, and the teacher's labels (distillation) or the residual's base."""
    with LimitBackend(native=cfg.native_limits).active():  # the run's native choice, kernels eager
        env = make_env(raw)
    start_notes(raw)
    pc = cfg.path_change  # path_change group (pathrl.envs.path_changes); absent or off: env itself
    if pc is not None and pc.enabled:
        env = PathChanges(env, pc)
    if _distills(cfg):
        return _with_teacher(cfg, env)
    return _with_base(cfg, env) if cfg.residual else env


def _distills(cfg: TrainAppCfg) -> bool:
    """Whether the run distils a teacher (RSL-RL's Distillation) rather than running PPO."""
    return cfg.agent["algorithm"]["class_name"] == "Distillation"


def _learn(runner: PathRLRunner, cfg: TrainAppCfg, remaining: int, raw: dict[str, Any]) -> None:
    """Run the `remaining` iterations under the run's limit code (native_limits, compile_limits; the env follows
    it); none left (killed after its last checkpoint): rewrite, and so close, the log the killed process left open."""
    if remaining:
        with LimitBackend.from_run(raw).active():
            runner.learn(num_learning_iterations=remaining)
    else:
        runner.logger.init_logging_writer()
        runner.logger.stop_logging_writer()


def _finish(runner: PathRLRunner, cfg: TrainAppCfg, env: Any, run_dir: Path, steps_per_iter: int) -> dict[str, Any]:
    """The run's summary (``steps_per_iter``: env steps per iteration), written to summary.json and returned."""
    last_ckpt = latest_checkpoint(run_dir)
    summary = {
        "experiment": cfg.experiment,
        "iterations": cfg.iterations,
        "env_steps": cfg.iterations * steps_per_iter,
        "wall_time_s": runner.wall_time_s(),
        "num_envs": env.num_envs,
        "steps_per_iteration": steps_per_iter,
        "knot_gap_norm": env.knot_gap,
        "checkpoint": last_ckpt.name if last_ckpt else None,
        "mean_reward": float(torch.tensor(list(runner.logger.rewbuffer)).mean()) if runner.logger.rewbuffer else None,
    }
    kept = json.loads((run_dir / "summary.json").read_text()).get("bias_search")
    if kept:  # the search before PPO: its wall time is in wall_time_s already, its env steps are added here
        summary.update({"bias_search": kept, "env_steps": summary["env_steps"] + int(kept.get("env_steps", 0))})
    write_json_atomic(run_dir / "summary.json", summary)
    return summary


def _schedules(runner: PathRLRunner, cfg: TrainAppCfg) -> None:
    """The per-iteration schedules of a run: critic warm-up, action-noise cap, learning rate, float32 switch."""
    total, warmup, anneal, decay = cfg.iterations, cfg.critic_warmup, cfg.std_anneal, cfg.lr_decay
    if warmup.freeze_normalizer:
        runner.freeze_actor_normalizer()
    if warmup.iterations > 0:
        runner.set_critic_warmup(warmup.iterations, warmup.learning_rate)
    if anneal is not None:
        runner.set_std_schedule(total, _init_std(cfg), anneal.final, anneal.start)
    if decay.final is not None:
        runner.set_lr_decay(total, decay.final, decay.start)
    if cfg.float32_from is not None:
        runner.set_float32_from(float32_iteration(cfg.float32_from, total))
    if cfg.task.curriculum is not None:
        apply_ball_curriculum(runner, cfg.task.curriculum)
    if cfg.reward_curriculum is not None:
        apply_reward_curriculum(runner, cfg.reward_curriculum)


def _check_lr_decay(cfg: TrainAppCfg) -> None:
    """ValueError for an `lr_decay` that would not act as written (bad values; PPO's adaptive schedule)."""
    decay = cfg.lr_decay
    if decay.final is None:
        return
    if not decay.final > 0 or not 0 <= decay.start < 1:
        raise ValueError(f"lr_decay: final must be > 0 and start in [0, 1), got {config_dict(decay)}")
    if cfg.agent["algorithm"].get("schedule", "fixed") != "fixed":
        raise ValueError("lr_decay needs agent.algorithm.schedule=fixed (the adaptive schedule sets the rate itself)")


def float32_iteration(fraction: Any, total: int) -> int:
    """The iteration at which ``float32_from`` (a fraction of the run's `total` iterations) switches the hidden
    layers to float32; ValueError outside [0, 1]."""
    try:
        f = float(fraction)
    except (TypeError, ValueError):
        f = math.nan
    if not 0.0 <= f <= 1.0:
        raise ValueError(f"float32_from must be a fraction of the iterations in [0, 1] or null, got {fraction!r}")
    return int(math.ceil(f * total))


def _init_std(cfg: TrainAppCfg) -> float:
    """The initial action std of the policy (the PPO actor or the distillation student)."""
    return float(cfg.agent[policy_role(cfg.agent)]["distribution_cfg"].get("init_std", 1.0))


def _with_teacher(cfg: TrainAppCfg, env: PathTrackingEnv):
    """The env of a distillation run: its observations carry the teacher controller's actions."""
    from pathrl.runs import make_controller
    from pathrl.train.distill import TeacherLabels

    if not cfg.teacher:
        raise ValueError("agent=distillation needs a teacher controller (teacher: {name: tray, ...})")
    if cfg.init_from:
        raise ValueError("init_from: a distillation run starts its student from scratch; remove init_from")
    if cfg.critic_warmup.iterations:
        raise ValueError("critic_warmup: a distillation run has no critic")
    if cfg.residual:
        raise ValueError("residual: a distillation run trains a whole policy, not a residual; remove residual")
    return TeacherLabels(env, make_controller(cfg.teacher, env))


def _with_base(cfg: TrainAppCfg, env: PathTrackingEnv) -> ResidualEnv:
    """The env of a residual run: it acts with the controller's action plus the policy's scaled residual."""
    from pathrl.runs import make_controller

    scale, spec = check_residual_cfg(cfg.residual)
    return ResidualEnv(env, make_controller(spec, env), scale)
