"""``pathrl-industrial``: motion-profile optimisation on the simulated industrial controller.

    pathrl-industrial table2 [key=value ...]   baseline + MPGD per evaluation trajectory -> out_table2 (Table II)
    pathrl-industrial speed  [key=value ...]   IWA + bisection on the speed command -> out_speed (cf. Table III)
    pathrl-industrial sweep  [key=value ...]   baseline max error over sweep_speeds -> out_sweep
    pathrl-industrial train  [key=value ...]   TD3 + PER policy -> run_dir (resume=true continues it)
    pathrl-industrial table4 [key=value ...]   the policies of table4_runs (ablations) -> out_table4
    pathrl-industrial validate [key=value ...] seed_runs on validation curves of the training family -> out_validation
    pathrl-industrial timing policy=RUN_DIR    per-iteration execution / decision times, t_opt model -> out_timing
    pathrl-industrial record traj=ROW method=mpgd|rl [policy=RUN_DIR] out=DIR [key=value ...]
                                               one row's optimisation, every execution -> DIR/industrial.mcap
                                               (``pathrl-view DIR`` shows it)

``speed speed_ilc=p|filtered`` runs the bisection around that ILC variant instead of MPGD.
``table2 policy=RUN_DIR`` adds the learned IWA (the run's newest checkpoint) beside MPGD; ``speed policy=RUN_DIR``
uses it as the inner loop instead of MPGD. ``policy=feedback:G`` is the fixed error-feedback policy a = (G, 0, 0).

Keys: ``conf/industrial/app.yaml`` (schema :class:`pathrl.industrial.config.IndustrialAppCfg`), e.g.
``rows='["Type 1 Easy"]' mpgd.k_max=20 controller.noise_mm=0.05``. Outputs are checked before the work and
written atomically.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from pathrl.cli.common import UserError, compose, output_dir, output_file, run_cli, to_container
from pathrl.storage import atomic_write

if TYPE_CHECKING:
    from pathrl.industrial.config import IndustrialAppCfg

__all__ = ["OUTPUT_KEYS", "RECORD_KEYS", "main"]

COMMANDS = ("table2", "speed", "sweep", "train", "table4", "record", "validate", "timing")
#: The config key of each command's output file (``train`` writes ``run_dir``).
OUTPUT_KEYS = {"table2": "out_table2", "speed": "out_speed", "sweep": "out_sweep", "table4": "out_table4",
               "validate": "out_validation", "timing": "out_timing"}
USAGE = "usage: pathrl-industrial {table2,speed,sweep,train,table4,record,validate,timing} [key=value ...]"
#: keys of ``record`` only (not config keys)
RECORD_KEYS = ("traj", "method", "out")


def _setup(overrides: Sequence[str]) -> tuple[IndustrialAppCfg, dict[str, Any], list]:
    """(the typed app config, the same as the composed dict (what a training run records), the evaluation rows)."""
    from pathrl.industrial.config import IndustrialAppCfg, app_cfg
    from pathrl.industrial.experiments import select_targets

    bad = [o for o in overrides if "=" not in o]
    if bad:
        raise UserError(f"expected key=value overrides, got {bad[0]!r}; {USAGE}")
    raw = to_container(compose("industrial/app", overrides, IndustrialAppCfg))
    try:
        app = app_cfg(raw)
        targets = select_targets(app.rows)
    except (TypeError, ValueError) as exc:
        raise UserError(str(exc)) from None
    return app, raw, targets


def _policy(run_dir: str):
    """(policy, column name): the deterministic policy of the newest valid checkpoint of `run_dir`; for
    ``feedback:G`` the fixed error-feedback policy a = (G, 0, 0) (move each waypoint by G times its error); None
    for an empty string."""
    if not run_dir:
        return None, "RL"
    if run_dir.startswith("feedback:"):
        from pathrl.industrial.config import feedback_gain

        try:
            gain = feedback_gain(run_dir)
        except ValueError as exc:
            raise UserError(str(exc)) from None
        return (lambda obs: np.tile([gain, 0.0, 0.0], (len(obs), 1))), f"EF({gain:g})"
    from pathrl.industrial.rl_train import load_agent

    try:
        agent, it = load_agent(Path(run_dir))
    except (ValueError, KeyError, TypeError) as exc:
        raise UserError(f"policy: {exc}") from None
    print(f"policy: {run_dir} at iteration {it}")
    clip = agent.params.action_clip
    return (agent.act if clip == 1.0 else (lambda obs: clip * agent.act(obs))), "RL"


def _train(app: IndustrialAppCfg, raw: dict[str, Any]) -> None:
    """``train``: the TD3 policy of `app` into its run_dir (the run records the composed config `raw`)."""
    import torch

    from pathrl.industrial.rl_train import train

    torch.set_num_threads(1)
    summary = train(Path(app.run_dir), app.rl, app.controller, app.waypoints, app.zone, app.resume, config=raw,
                    progress=True)
    print(f"trained {app.run_dir}: {summary}")


def _write(path: str, text: str) -> None:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, text)
    print(f"wrote {out}")


def _main(argv: list[str]) -> None:
    if not argv or argv[0] in ("-h", "--help"):
        if argv:
            print(__doc__)
            return
        raise UserError(f"missing command; {USAGE}")
    cmd, rest = argv[0], argv[1:]
    if cmd not in COMMANDS:
        raise UserError(f"unknown command {cmd!r}; choose one of {', '.join(COMMANDS)}")
    if cmd == "record":
        _record(rest)
        return
    from pathrl.industrial import experiments, tables
    from pathrl.industrial.iwa_env import IWASettings

    cfg, raw, targets = _setup(rest)
    if cmd == "train":
        output_dir(cfg.run_dir, "run_dir")
    else:
        output_file(getattr(cfg, OUTPUT_KEYS[cmd]), OUTPUT_KEYS[cmd])
    command = " ".join(["pathrl-industrial", *argv])
    note = ("Paper values: Wen et al., RobotStudio simulation of an ABB IRB 6640 (Table II/III); ours: the "
            "simulated controller of pathrl.industrial (a different controller, so compare trends, not digits). "
            "t_opt is our wall time on one CPU core; the paper's includes ~12 s of RobotStudio per execution.")
    t0 = time.perf_counter()
    try:
        if cmd == "train":
            _train(cfg, raw)
            return
        controller, mpgd, k_max = cfg.controller, cfg.mpgd, cfg.rl.k_max
        if cmd == "table2":
            policy, name = _policy(cfg.policy)
            iwa = IWASettings(cfg.waypoints, cfg.zone, k_max)
            rows = experiments.run_table2(targets, controller, mpgd, iwa, cfg.seed, policy,
                                          cfg.ilc.variants(controller.model))
            text = tables.table2_markdown(rows, command, note, name)
            if policy is not None and cfg.seed_runs:
                text += _seed_summary(cfg, targets, rows)
            out = cfg.out_table2
        elif cmd == "speed":
            policy, name = _policy(cfg.policy)
            iwa = IWASettings(cfg.waypoints, cfg.zone, k_max)
            ilc = _speed_ilc(cfg)
            rows = experiments.run_speed(targets, controller, mpgd, cfg.search, iwa, cfg.seed, policy, ilc)
            name = name if policy is not None else ("MPGD" if ilc is None else f"ILC {cfg.speed_ilc}")
            text = tables.table3_markdown(rows, command, note, name)
            out = cfg.out_speed
        elif cmd == "table4":
            text, out = _table4(cfg, targets, command, note), cfg.out_table4
        elif cmd == "validate":
            text, out = _validate(cfg, command), cfg.out_validation
        elif cmd == "timing":
            text, out = _timing(cfg, targets, command), cfg.out_timing
        else:
            speeds = [float(v) for v in cfg.sweep_speeds]
            errs = experiments.baseline_sweep(targets, speeds, controller, cfg.waypoints, cfg.zone)
            text = experiments.sweep_markdown(targets, speeds, errs, command)
            out = cfg.out_sweep
    except ValueError as exc:
        raise UserError(str(exc)) from None
    print(text)
    _write(out, text)
    print(f"{cmd} took {time.perf_counter() - t0:.1f} s")


def _speed_ilc(cfg: IndustrialAppCfg):
    """The ILC settings of ``speed_ilc`` (gains and updates from the ``ilc`` keys), or None when it is empty."""
    from pathrl.industrial.ilc import ILCParams

    if not cfg.speed_ilc:
        return None
    gain = cfg.ilc.gain_p if cfg.speed_ilc == "p" else cfg.ilc.gain_filtered
    return ILCParams(cfg.speed_ilc, gain, k_max=cfg.ilc.k_max)


def _seed_summary(cfg: IndustrialAppCfg, targets, mpgd_rows) -> str:
    """The per-seed lines of ``seed_runs`` on the Table II rows, with mean and min-max over the seeds."""
    from pathrl.industrial import seeds

    summaries = [seeds.summarise(run, _policy_rows(cfg, targets, run), mpgd_rows) for run in cfg.seed_runs]
    return "\n".join([
        "## Seeds of the policy's configuration", "",
        "The RL columns above are one shipped policy; every seed of its configuration (`seed_runs`) on the same "
        "rows, against the same MPGD runs (ratios summed over the rows both reach; t_opt is wall time):", "",
        *seeds.seed_table_markdown({"TD3 + PER": summaries}), ""])


def _policy_rows(cfg: IndustrialAppCfg, targets, run: str) -> list:
    """The rows of `targets` optimised by the policy of run directory `run` (:func:`seeds.run_policy_rows`)."""
    from pathrl.industrial import seeds

    return seeds.run_policy_rows(targets, _policy(run)[0], cfg.controller, cfg.waypoints, cfg.zone, cfg.rl.k_max)


def _table4(cfg: IndustrialAppCfg, targets, command: str, note: str) -> str:
    """Table IV: per row the first run of each variant; then every run's summary and mean / min-max per variant."""
    from pathrl.industrial import seeds, tables

    try:
        variants = seeds.parse_runs(cfg.table4_runs)
    except ValueError as exc:
        raise UserError(f"table4_runs: {exc}") from None
    results = {run: _policy_rows(cfg, targets, run) for dirs in variants.values() for run in dirs}
    first = {name: [(r.name, r.err_mm, r.itr) for r in results[dirs[0]]] for name, dirs in variants.items()}
    text = tables.table4_markdown(first, command, note)
    summaries = {name: [seeds.summarise(run, results[run]) for run in dirs] for name, dirs in variants.items()}
    return "\n".join([
        text, "## Seeds per variant", "",
        "The per-row columns above are each variant's first run; all its runs (seeds) below, with mean and min-max "
        "over them:", "", *seeds.seed_table_markdown(summaries, with_ratios=False), ""])


def _validate(cfg: IndustrialAppCfg, command: str) -> str:
    """Score the ``seed_runs`` on the validation set (:mod:`pathrl.industrial.seeds`)."""
    from pathrl.industrial import seeds

    if not cfg.seed_runs:
        raise UserError("validate: seed_runs is empty (give the run dirs to compare)")
    try:
        targets = seeds.validation_targets(int(cfg.validation_n), int(cfg.validation_seed))
    except ValueError as exc:
        raise UserError(str(exc)) from None
    results = {run: _policy_rows(cfg, targets, run) for run in cfg.seed_runs}
    return seeds.validation_markdown(results, cfg.rl.k_max, command, int(cfg.validation_n), int(cfg.validation_seed))


def _timing(cfg: IndustrialAppCfg, targets, command: str) -> str:
    """Per-iteration times of execution, measurement, MPGD and policy decisions, and the t_opt cost model."""
    import torch

    from pathrl.industrial import timing

    if not cfg.policy:
        raise UserError("timing: needs policy=RUN_DIR (the policy whose decisions are timed)")
    torch.set_num_threads(1)
    policy = _policy(cfg.policy)[0]
    rows = timing.time_rows(targets, cfg.controller, cfg.mpgd, policy, cfg.waypoints, cfg.zone, cfg.rl.k_max, cfg.seed)
    return timing.timing_markdown(rows, command)


def _record_keys(argv: Sequence[str]) -> tuple[dict[str, str], list[str]]:
    """(the ``record`` keys traj/method/out, the remaining config overrides); UserError if one is missing."""
    own = {k: v for k, _, v in (a.partition("=") for a in argv) if k in RECORD_KEYS}
    missing = [k for k in RECORD_KEYS if not own.get(k)]
    if missing:
        raise UserError(f"record: missing {', '.join(f'{k}=' for k in missing)}; usage: pathrl-industrial record "
                        "traj=ROW method=mpgd|rl [policy=RUN_DIR] out=DIR [key=value ...]")
    if own["method"] not in ("mpgd", "rl"):
        raise UserError(f"record: method must be mpgd or rl, got {own['method']!r}")
    return own, [a for a in argv if a.partition("=")[0] not in RECORD_KEYS]


def _record(argv: Sequence[str]) -> None:
    """``record``: one evaluation row's optimisation with every execution, written to out/industrial.mcap."""
    import torch

    from pathrl.industrial.experiments import select_targets
    from pathrl.industrial.iwa_env import IWASettings
    from pathrl.industrial.record import Optimiser, record_optimisation

    own, rest = _record_keys(argv)
    cfg, _, _ = _setup(rest)
    output_dir(own["out"], "out", ("industrial.mcap",))
    try:
        target = select_targets([own["traj"]])[0]
    except ValueError as exc:
        raise UserError(f"record: traj: {exc}") from None
    run = cfg.policy
    if own["method"] == "mpgd" and run:
        raise UserError("record: policy= is for method=rl (MPGD has no policy)")
    if own["method"] == "rl":
        if not run:
            raise UserError("record: method=rl needs policy=RUN_DIR (or policy=feedback:<gain>)")
        if not run.startswith("feedback:") and not Path(run).is_dir():
            raise UserError(f"record: policy: no such run directory: {run}")
    torch.set_num_threads(1)
    policy, name = _policy(run) if own["method"] == "rl" else (None, "MPGD")
    try:
        out, result, kept = record_optimisation(
            target, Optimiser(own["method"], cfg.mpgd, policy), cfg.controller, Path(own["out"]),
            iwa=IWASettings(cfg.waypoints, cfg.zone, cfg.rl.k_max), seed=cfg.seed,
            meta={"policy": run, "method_name": name, "command": " ".join(["pathrl-industrial", "record", *argv])})
    except ValueError as exc:
        raise UserError(f"record: {exc}") from None
    errs = [i.errors.max_pos_mm for i in kept]
    print(f"{target.name} with {name}: max error {errs[0]:.3f} mm (baseline) -> {min(errs):.3f} mm (best), "
          f"{len(kept)} executions, t_opt {result.t_opt:.2f} s")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.2f} MB); view with: pathrl-view {out.parent}")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``pathrl-industrial COMMAND [key=value ...]`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    sys.exit(main())
