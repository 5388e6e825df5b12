"""Default parameters of the path generators (``random``, ``target_point``, ``ball_balancing``) and their checks.

The values equal ``conf/dataset/<kind>.yaml``'s ``params`` (tests/test_dataset_generate.py checks it); their key
order is the order of ``generator.params`` in a generated ``dataset.json``. The reasons for the values:
docs/datasets.md.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

from pathrl.dataset.io import DatasetError

__all__ = ["APPROACHES", "DEFAULT_PARAMS", "KINDS", "resolve_params", "smoothing_range"]

KINDS = ("random", "target_point", "ball_balancing")
APPROACHES = ("saturated", "pursuit", "pd")  # target_point motion toward each goal

_COMMON = {
    "chunk_size": 100,  # paths per chunk (unit of seeding and of parallel work)
    "batch_size": 256,  # at most this many candidate trajectories simulated together
    "dt": 0.1,  # decision step (s)
    "substeps": 4,  # recorded (and collision-checked) samples per decision step
    "max_duration": 60.0,  # longest simulated motion per candidate (s)
    "max_rewinds": 20,
    "knot_spacing": 0.1,  # stored knots: distance resampling (rad)
    "limit_margin": 0.02,  # motions stay this far inside the position limits (room for spline overshoot)
    "check_spacing": 0.05,  # final check of the stored path: collisions every 0.05 rad (limits every 0.01)
}

DEFAULT_PARAMS: dict[str, dict[str, Any]] = {
    "random": {
        **_COMMON,
        "length_range": {
            "iiwa7": [19.5, 26.0],
            "armar6": [21.6, 25.5],
            "armar4": [18.0, 22.9],
            "default": [19.5, 26.0],
        },
        "action_smoothing": 0.0,
        "checkpoint_steps": 5,
        "oversample": 1.4,  # candidates per missing path (~25 % are dropped after repeated collisions)
        "default_knots": {"strategy": "curvature", "spacing": 0.3, "base_spacing": 0.1},
    },
    "target_point": {
        **_COMMON,
        "length_range": {"iiwa7": [22.0, 28.9], "armar4": [23.7, 29.4], "default": [22.0, 28.9]},
        "oversample": 1.1,
        "approach": "saturated",  # saturated | pursuit | pd (module docstring)
        "cruise": 0.8,  # fraction of the velocity limits (saturated, pursuit)
        "gain": 6.0,
        "action_noise": 0.1,
        "goal_tolerance": 0.4,
        "goal_timeout": 6.0,  # s without reaching the goal -> new goal
        "min_goal_distance": 0.5,
        "ik_iterations": 150,
        "ik_tolerance": 0.005,  # m
        "ik_rounds": 8,
        "ik_candidates": 4,  # random targets solved at once per goal
        "goal_batch": 3,  # goals queued per candidate at each (batched) IK refill
        "default_knots": {"strategy": "curvature", "spacing": 0.3, "base_spacing": 0.1},
    },
    "ball_balancing": {
        "chunk_size": 10,
        "length_range": [3.2, 5.1],
        "length_beta": [1.5, 3.5],
        "waypoint_step": [0.8, 1.6],
        "waypoint_turn": 0.6,
        "q7_max": 0.006,
        "start_region": None,  # [[lo, hi]] rad for q1, q2, q4 at the start (None: the position limits)
        "step_weights": None,  # factors on the step direction's q1, q2, q4 (None: 1, 1, 1)
        "region": None,  # [[lo, hi]] rad for q1, q2, q4 at every waypoint (None: the position limits)
        "sweep": False,  # start heading +q1 and never turn q1 back (the authors' set sweeps the base)
        "reflections": False,  # each path times one of the authors' 4 joint sign patterns, drawn uniformly
        "check_spacing": 0.05,
        "knot_spacing": 0.3,
        "max_tries": 200,
        "default_knots": {"strategy": "distance", "spacing": 0.3, "base_spacing": 0.1},
    },
}

def smoothing_range(value: float | Sequence[float]) -> tuple[float, float]:
    """``action_smoothing`` as (min, max): a number rho is (rho, rho); a [min, max] pair is drawn from per candidate.

    Raises DatasetError unless 0 <= min <= max < 1.
    """
    try:
        lo, hi = (float(value), float(value)) if not isinstance(value, Sequence) else (float(x) for x in value)
    except (TypeError, ValueError):
        raise DatasetError(f"dataset.params.action_smoothing: expected rho or [min, max], got {value!r}") from None
    if not 0.0 <= lo <= hi < 1.0:
        raise DatasetError(f"dataset.params.action_smoothing: need 0 <= min <= max < 1, got [{lo}, {hi}]")
    return lo, hi


def resolve_params(kind: str, robot_name: str, params: Mapping[str, Any] | None) -> dict[str, Any]:
    """Defaults for `kind` updated by `params`; per-robot ``length_range`` mappings resolved."""
    if kind not in DEFAULT_PARAMS:
        raise DatasetError(f"dataset.kind: unknown generator {kind!r}; choose one of {list(KINDS)}")
    out = copy.deepcopy(DEFAULT_PARAMS[kind])
    unknown = sorted(set(params or {}) - set(out))
    if unknown:
        raise DatasetError(f"dataset.params: unknown keys {unknown} for {kind!r}; valid: {sorted(out)}")
    for key, value in (params or {}).items():
        out[key] = copy.deepcopy(dict(value) if isinstance(value, Mapping) else value)
    lr = out["length_range"]
    if isinstance(lr, Mapping):
        lr = lr.get(robot_name, lr.get("default"))
    try:
        lo, hi = (float(x) for x in lr)
    except (TypeError, ValueError):
        raise DatasetError(f"dataset.params.length_range: expected [min, max], got {lr!r}") from None
    if not 0 < lo <= hi:
        raise DatasetError(f"dataset.params.length_range: need 0 < min <= max, got [{lo}, {hi}]")
    out["length_range"] = [lo, hi]
    for key in ("chunk_size", "batch_size", "substeps"):
        if key in out and int(out[key]) < 1:
            raise DatasetError(f"dataset.params.{key} must be >= 1, got {out[key]}")
    if "approach" in out and out["approach"] not in APPROACHES:
        raise DatasetError(f"dataset.params.approach: expected one of {list(APPROACHES)}, got {out['approach']!r}")
    if "action_smoothing" in out:
        smoothing_range(out["action_smoothing"])
    for key in ("cruise", "gain"):
        if key in out and not float(out[key]) > 0:
            raise DatasetError(f"dataset.params.{key} must be > 0, got {out[key]}")
    return out
