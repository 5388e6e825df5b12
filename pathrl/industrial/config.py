"""Config schema of ``pathrl-industrial`` (YAML in ``conf/industrial/app.yaml``; Hydra overrides on the CLI)."""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, fields
from typing import Any

from pathrl.industrial.controller import ControllerParams
from pathrl.industrial.ilc import ILCColumns
from pathrl.industrial.mpgd import MPGDParams
from pathrl.industrial.rl import RLParams
from pathrl.industrial.speed_search import SearchParams

__all__ = ["IndustrialAppCfg", "app_cfg", "build", "check_app", "feedback_gain"]


@dataclass
class IndustrialAppCfg:
    """Keys of the app config: the controller model, MPGD and bisection settings, the evaluation rows (names of
    the paper's Table II rows; empty = all), waypoints and zone of the baseline profile, speeds of the baseline
    sweep (mm/s), output files (relative to the working directory) and the seed; for the learned policy the TD3
settings, the training run directory, whether to resume it, and the run directory whose newest checkpoint
``table2`` evaluates beside MPGD (empty: no RL columns); ``table4`` evaluates the run directories of
``table4_runs`` (``NAME=RUN_DIR[,RUN_DIR...]`` entries: several run dirs are seeds of one variant, summarised as
mean and min-max); ``seed_runs`` are the run dirs of the seeds of the main configuration (``table2`` with a policy
adds their per-seed summary, ``validate`` scores them on ``validation_n`` training-family curves drawn with
``validation_seed``, :mod:`pathrl.industrial.seeds`); ``timing`` writes where t_opt goes to ``out_timing``;
``speed_ilc`` ("p" or "filtered"; empty = off) makes ``speed``'s inner IWA that ILC variant (``ilc`` gains)."""

    controller: ControllerParams = field(default_factory=ControllerParams)
    mpgd: MPGDParams = field(default_factory=MPGDParams)
    search: SearchParams = field(default_factory=SearchParams)
    rl: RLParams = field(default_factory=RLParams)
    ilc: ILCColumns = field(default_factory=ILCColumns)
    run_dir: str = "runs/industrial_td3/seed0"
    resume: bool = False
    policy: str = ""
    table4_runs: list[str] = field(default_factory=list)
    out_table4: str = "results/industrial_table4.md"
    seed_runs: list[str] = field(default_factory=list)
    validation_n: int = 30
    validation_seed: int = 0
    out_validation: str = "results/industrial_validation.md"
    out_timing: str = "results/industrial_timing.md"
    rows: list[str] = field(default_factory=list)
    waypoints: int = 100
    zone: float = 10.0
    sweep_speeds: list[float] = field(default_factory=lambda: [250.0, 400.0, 700.0, 1100.0])
    out_table2: str = "results/industrial_table2.md"
    out_speed: str = "results/industrial_speed.md"
    speed_ilc: str = ""
    out_sweep: str = "results/industrial_baseline_sweep.md"
    seed: int = 0


def _numbers(node: Any, prefix: str = "") -> Iterator[tuple[str, float]]:
    """(dotted key, value) of every float in a config mapping (lists included, as ``key[i]``)."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _numbers(v, f"{prefix}{k}.")
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _numbers(v, f"{prefix.rstrip('.')}[{i}].")
    elif isinstance(node, float):
        yield prefix.rstrip("."), node


def app_cfg(cfg: dict[str, Any]) -> IndustrialAppCfg:
    """The typed app config of a composed config mapping (every key of the schema), its values checked first
    (:func:`check_app`; ValueError on a bad value) and its groups as their parameter dataclasses (:func:`build`)."""
    controller, mpgd, search, rl = build(cfg)
    groups = {"controller": controller, "mpgd": mpgd, "search": search, "rl": rl, "ilc": ILCColumns(**cfg["ilc"])}
    return IndustrialAppCfg(**groups, **{f.name: cfg[f.name] for f in fields(IndustrialAppCfg) if f.name not in groups})


def check_app(cfg: dict[str, Any]) -> None:
    """ValueError (one line) for app values that would run into a wrong or empty result: NaN / inf anywhere, an
    empty or non-positive ``sweep_speeds``, fewer than 2 ``waypoints``, a negative ``zone``, a bad ``policy``."""
    for key, value in _numbers(cfg):
        if not math.isfinite(value):
            raise ValueError(f"{key} must be a finite number, got {value}")
    speeds = cfg["sweep_speeds"]
    if not speeds or any(not isinstance(v, (int, float)) or isinstance(v, bool) or v <= 0 for v in speeds):
        raise ValueError(f"sweep_speeds must be a non-empty list of speeds > 0 (mm/s), got {speeds}")
    if cfg["waypoints"] < 2:
        raise ValueError(f"waypoints must be >= 2, got {cfg['waypoints']}")
    if not cfg["zone"] >= 0:
        raise ValueError(f"zone must be >= 0 (mm), got {cfg['zone']}")
    if cfg["speed_ilc"] not in ("", "p", "filtered"):
        raise ValueError(f"speed_ilc must be empty, p or filtered, got {cfg['speed_ilc']!r}")
    if cfg["speed_ilc"] and cfg["policy"]:
        raise ValueError("speed: give either policy or speed_ilc, not both")
    if str(cfg["policy"]).startswith("feedback:"):
        feedback_gain(cfg["policy"])


def feedback_gain(spec: str) -> float:
    """The gain G of ``policy=feedback:G`` (a finite number); ValueError otherwise."""
    try:
        gain = float(spec.split(":", 1)[1])
    except ValueError:
        raise ValueError(f"policy: expected feedback:<gain>, got {spec!r}") from None
    if not math.isfinite(gain):
        raise ValueError(f"policy: the feedback gain must be a finite number, got {spec!r}")
    return gain


def build(cfg: dict[str, Any]) -> tuple[ControllerParams, MPGDParams, SearchParams, RLParams]:
    """The parameter dataclasses of a composed config mapping, its values checked first (:func:`check_app`;
    ValueError on a bad value)."""
    check_app(cfg)
    return (ControllerParams(**cfg["controller"]), MPGDParams(**cfg["mpgd"]), SearchParams(**cfg["search"]),
            RLParams(**cfg["rl"]))
