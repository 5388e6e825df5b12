"""The device a run's tensors live on: which names are valid (:func:`resolve_device`), which tasks can run there
(:func:`check_run_device`), and a walker that finds any tensor left elsewhere (:func:`off_device`).

Training builds its env, its policy and its rollout storage on the run config's ``device`` (``cpu``, ``cuda``,
``cuda:N``). Evaluation and deployment build on :data:`EVAL_DEVICE`, whatever device the run was trained on, so
a run trained on a GPU evaluates on a CPU-only machine. PyBullet scenes live in CPU worker processes: a task that
simulates in PyBullet trains on the CPU only.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from typing import Any

import torch
from torch import Tensor, nn

__all__ = ["DEVICE_RE", "EVAL_DEVICE", "WALKED", "DeviceError", "check_run_device", "native_note", "off_device",
           "resolve_device", "same_device"]

#: The device evaluation, deployment and export build their env on (the saved run's ``device`` is not used).
EVAL_DEVICE = "cpu"

#: The device names a run config may give: ``cpu``, ``cuda``, ``cuda:N``.
DEVICE_RE = re.compile(r"^(cpu|cuda(:\d+)?)$")


class DeviceError(ValueError):
    """A device name that is misspelt, absent on this machine, or unfit for the run's task (one line)."""


def _check_name(text: str) -> None:
    """DeviceError for a device name that is not ``cpu``, ``cuda`` or ``cuda:N``."""
    if not DEVICE_RE.match(text):
        raise DeviceError(f"device={text}: expected cpu, cuda or cuda:N (N counts from 0)")


def resolve_device(name: Any) -> torch.device:
    """The torch device of a config's ``device`` value; DeviceError (one line) for a misspelt name, for CUDA where
    this torch sees no CUDA device, and for ``cuda:N`` beyond the device count."""
    text = str(name).strip()
    _check_name(text)
    device = torch.device(text)
    if device.type == "cuda":
        count = torch.cuda.device_count() if torch.cuda.is_available() else 0
        if count == 0:
            build = "a CPU build" if torch.version.cuda is None else f"CUDA {torch.version.cuda}, no device visible"
            raise DeviceError(f"device={text} but this torch ({torch.__version__}, {build}) has no CUDA device; "
                              "use device=cpu")
        if device.index is not None and device.index >= count:
            raise DeviceError(f"device={text} but this machine has {count} CUDA device(s): cuda:0 .. cuda:{count - 1}")
    return device


def _pybullet_task(cfg: Mapping[str, Any]) -> str | None:
    """The name of the run config's task if it simulates in PyBullet (``task.backend=pybullet``), else None."""
    task = cfg.get("task") or {}
    if task.get("feedback") is not None and task.get("backend") == "pybullet":
        return str(task.get("name") or task["feedback"])
    return None


def check_run_device(cfg: Mapping[str, Any]) -> torch.device:
    """The device of a resolved run config, checked before any work: a valid name (:func:`resolve_device`), and the
    CPU for a task simulated in PyBullet (its scenes and their state live in CPU worker processes)."""
    text = str(cfg.get("device", "cpu")).strip()
    _check_name(text)
    task = _pybullet_task(cfg)
    if task is not None and text != "cpu":
        hint = " or task.backend=analytic"
        raise DeviceError(f"device={text}: task {task} simulates in PyBullet, on the CPU only; use device=cpu{hint}")
    return resolve_device(text)


def same_device(a: torch.device | str, b: torch.device | str) -> bool:
    """Whether two devices are the same (``cuda`` is the current CUDA device, ``cuda:0`` on one GPU)."""
    a, b = torch.device(a), torch.device(b)
    if a.type != b.type:
        return False
    if a.type != "cuda" or a.index == b.index:
        return True
    current = torch.cuda.current_device()
    return (current if a.index is None else a.index) == (current if b.index is None else b.index)


def native_note(device: torch.device | str, native_wanted: bool, native_available: bool) -> str | None:
    """One line for a run whose native limit kernels are off because of its device (they take CPU tensors only);
    None on the CPU or where they would not run anyway."""
    device = torch.device(device)
    if device.type == "cpu" or not (native_wanted and native_available):
        return None
    return (f"the native limit kernels take CPU tensors only; on {device} the torch code computes the limits "
            "(native_limits=false says so)")


#: Modules whose objects :func:`off_device` looks into (besides containers, modules and TensorDicts).
WALKED = ("pathrl.",)


def off_device(root: Any, device: torch.device | str, name: str = "env", modules: tuple[str, ...] = WALKED,
               max_depth: int = 8) -> list[str]:
    """Dotted names of every tensor and ``torch.Generator`` reachable from `root` that is not on `device`.

    Looked into: attributes of objects whose class is defined in `modules` (the env, its feedback, controllers,
    wrappers, path sets, limits), dicts, lists, tuples, TensorDicts, and the parameters and buffers of
    ``nn.Module`` s (with their public attributes, if the module's class is in `modules`). Each object once."""
    device = torch.device(device)
    out: list[str] = []
    seen: set[int] = set()
    stack: list[tuple[str, Any, int]] = [(name, root, 0)]
    while stack:
        path, obj, depth = stack.pop()
        if isinstance(obj, Tensor | torch.Generator):
            if not same_device(obj.device, device):
                out.append(f"{path} ({obj.device})")
            continue
        if id(obj) in seen or depth > max_depth:
            continue
        seen.add(id(obj))
        stack.extend((p, v, depth + 1) for p, v in _children(path, obj, modules))
    return sorted(out)


def _children(path: str, obj: Any, modules: tuple[str, ...]) -> Iterator[tuple[str, Any]]:
    """(name, value) of what :func:`off_device` looks at inside `obj`."""
    from tensordict import TensorDictBase

    if isinstance(obj, TensorDictBase):
        for key, v in obj.items(include_nested=True, leaves_only=True):
            yield f"{path}[{key!r}]", v
    elif isinstance(obj, Mapping):
        for i, (key, v) in enumerate(obj.items()):
            yield f"{path}[{key!r}]" if isinstance(key, str | int) else f"{path}[{i}]", v
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            yield f"{path}[{i}]", v
    elif isinstance(obj, nn.Module):
        yield from ((f"{path}.{n}", t) for n, t in obj.named_parameters())
        yield from ((f"{path}.{n}", t) for n, t in obj.named_buffers())
        if type(obj).__module__.startswith(modules):
            yield from ((f"{path}.{n}", v) for n, v in vars(obj).items() if not n.startswith("_"))
    elif hasattr(obj, "__dict__") and not isinstance(obj, type) and type(obj).__module__.startswith(modules):
        yield from ((f"{path}.{n}", v) for n, v in vars(obj).items())
