"""The RSL-RL train config (``agent``, keys verbatim) checked by type and range before a run starts.

``agent`` is free-form in the schema (RSL-RL's keys, passed through), so Hydra takes ``agent.algorithm.gamma=-3``
or ``agent.actor.hidden_dims=abc`` as written; RSL-RL would train on the first and fail with a traceback deep in
its runner on the second, after the run directory was made. :func:`check_agent` refuses both in one line. Keys not
listed here are passed to RSL-RL unchecked.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["ACTIVATIONS", "check_agent"]

#: rsl-rl's activation names (rsl_rl.utils.resolve_nn_activation).
ACTIVATIONS = ("elu", "selu", "relu", "crelu", "lrelu", "tanh", "sigmoid", "softplus", "gelu", "swish", "mish",
               "identity")

Check = Callable[[Any], str | None]  # the value -> what it must be (None: fine)


def _int(low: int) -> Check:
    """An integer >= `low` (not a bool)."""
    return lambda v: None if isinstance(v, int) and not isinstance(v, bool) and v >= low else f"an integer >= {low}"


def _num(low: float, high: float = math.inf, low_open: bool = True, none: bool = False) -> Check:
    """A finite number in (`low`, `high`] (``[low, high]`` unless `low_open`); `none`: null allowed."""
    def check(v: Any) -> str | None:
        if v is None and none:
            return None
        ok = isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
        ok = ok and (v > low if low_open else v >= low) and v <= high
        if high < math.inf:
            span = f"in {'(' if low_open else '['}{low:g}, {high:g}]"
        else:
            span = f"{'>' if low_open else '>='} {low:g}"
        return None if ok else f"a number {span}" + (" or null" if none else "")
    return check


def _bool(v: Any) -> str | None:
    return None if isinstance(v, bool) else "true or false"


def _one_of(*names: str) -> Check:
    return lambda v: None if v in names else f"one of {', '.join(names)}"


def _dims(v: Any) -> str | None:
    ok = isinstance(v, (list, tuple)) and all(isinstance(d, int) and not isinstance(d, bool) and d >= 1 for d in v)
    return None if ok else "a list of positive integers, e.g. [256, 128]"


#: Checked keys: top level and ``algorithm`` (RSL-RL's PPO and Distillation arguments).
RUNNER = {"num_steps_per_env": _int(1), "save_interval": _int(1), "check_for_nan": _bool}
ALGORITHM = {
    "class_name": _one_of("PPO", "Distillation"),
    "num_learning_epochs": _int(1), "num_mini_batches": _int(1), "gradient_length": _int(1),
    "clip_param": _num(0.0), "gamma": _num(0.0, 1.0), "lam": _num(0.0, 1.0),
    "value_loss_coef": _num(0.0, low_open=False), "entropy_coef": _num(0.0, low_open=False),
    "learning_rate": _num(0.0), "max_grad_norm": _num(0.0, none=True), "desired_kl": _num(0.0, none=True),
    "schedule": _one_of("adaptive", "fixed"), "optimizer": _one_of("adam", "adamw", "sgd", "rmsprop"),
    "use_clipped_value_loss": _bool, "normalize_advantage_per_mini_batch": _bool, "loss_type": _one_of("mse", "huber"),
}
#: Checked keys of the networks (``actor``, ``critic``, ``student``).
MODEL = {"hidden_dims": _dims, "activation": _one_of(*ACTIVATIONS), "obs_normalization": _bool,
         "hidden_dtype": _one_of("float32", "bfloat16"), "rnn_type": _one_of("gru", "lstm"),
         "rnn_hidden_dim": _int(1), "rnn_num_layers": _int(1)}
MODELS = ("actor", "critic", "student")


def _check_group(values: Mapping[str, Any], checks: Mapping[str, Check], prefix: str) -> None:
    """ValueError naming the first key of `values` that fails its check."""
    for key, check in checks.items():
        if key in values:
            need = check(values[key])
            if need is not None:
                raise ValueError(f"{prefix}{key} must be {need}, got {values[key]!r}")


def check_agent(agent: Any) -> None:
    """Raise ValueError (one line naming the key, what it must be and what it is) for a value of the RSL-RL train
    config that is of the wrong type or out of range: PPO's gamma and lambda in (0, 1], learning rate, clip and
    the KL target > 0, epochs, mini-batches and steps positive integers, network dims a list of positive integers."""
    if not isinstance(agent, Mapping):
        raise ValueError(f"agent must be a mapping of RSL-RL settings, got {type(agent).__name__}")
    _check_group(agent, RUNNER, "agent.")
    algorithm = agent.get("algorithm")
    if not isinstance(algorithm, Mapping):
        raise ValueError(f"agent.algorithm must be a mapping with class_name PPO or Distillation, got {algorithm!r}")
    _check_group(algorithm, ALGORITHM, "agent.algorithm.")
    if algorithm.get("class_name") == "PPO" and "max_grad_norm" in algorithm and algorithm["max_grad_norm"] is None:
        raise ValueError("agent.algorithm.max_grad_norm must be a number > 0 for PPO, got None")
    for name in MODELS:
        model = agent.get(name)
        if model is None:
            continue
        if not isinstance(model, Mapping):
            raise ValueError(f"agent.{name} must be a mapping (class_name, hidden_dims, ...), got {model!r}")
        _check_group(model, MODEL, f"agent.{name}.")
        dist = model.get("distribution_cfg")
        if dist is not None:
            if not isinstance(dist, Mapping):
                raise ValueError(f"agent.{name}.distribution_cfg must be a mapping, got {dist!r}")
            _check_group(dist, {"init_std": _num(0.0)}, f"agent.{name}.distribution_cfg.")
