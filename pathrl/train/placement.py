"""Where a run's tensors are, and the lines a run prints about it at its start: the native limit kernels off on a
GPU, bfloat16 emulated on the CPU or GPU, a resume that is not bit-exact (CUDA), a tensor left off the run's device."""

from __future__ import annotations

import sys
from typing import Any

import torch
from rsl_rl.runners import OnPolicyRunner

from pathrl import native
from pathrl.envs.device import native_note, off_device
from pathrl.limits.backend import LimitBackend
from pathrl.policy.models import bfloat16_roles, bfloat16_warning

__all__ = ["gpu_bfloat16_warning", "placement_warning", "resume_notes", "start_notes", "stray_tensors"]


def start_notes(cfg: dict[str, Any]) -> None:
    """One line each on stderr: bfloat16 on a CPU that emulates it (a PPO update ~13x slower; measured on CPU runs
    only), bfloat16 on a GPU without it (compute capability < 8), the native limit kernels off on a GPU."""
    device = torch.device(str(cfg.get("device", "cpu")))
    if device.type == "cpu":
        if slow := bfloat16_warning(cfg["agent"]):
            print(f"warning: {slow}", file=sys.stderr)
        return
    if slow := gpu_bfloat16_warning(cfg["agent"], device):
        print(f"warning: {slow}", file=sys.stderr)
    if note := native_note(device, LimitBackend.from_run(cfg).native, native.available()):
        print(f"note: {note}", file=sys.stderr)


def gpu_bfloat16_warning(agent: dict[str, Any], device: torch.device) -> str | None:
    """One line for a run on a CUDA device without native bfloat16 (compute capability < 8.0: torch emulates it)
    whose models ask for bfloat16 hidden layers; None otherwise."""
    roles = bfloat16_roles(agent)
    if device.type != "cuda" or not roles or torch.cuda.is_bf16_supported(including_emulation=False):
        return None
    overrides = " ".join(f"agent.{r}.hidden_dtype=float32" for r in roles)
    return (f"{torch.cuda.get_device_name(device)} has no native bfloat16 (compute capability < 8.0): add "
            f"{overrides} for a faster run")


def stray_tensors(runner: OnPolicyRunner) -> list[str]:
    """The tensors of the runner's env (wrappers, controller, feedback included) and algorithm (models, rollout
    storage) that are not on the run's device (:func:`pathrl.envs.device.off_device`); empty when all are."""
    return off_device({"env": runner.env, "alg": runner.alg}, runner.device, "runner", ("pathrl.", "rsl_rl."))


def placement_warning(runner: OnPolicyRunner) -> None:
    """One line on stderr if a tensor of the run is not on its device (a step would fail or copy every time)."""
    if stray := stray_tensors(runner):
        print(f"warning: {len(stray)} tensors are not on the run's device {runner.device}: {', '.join(stray[:4])}",
              file=sys.stderr)


def resume_notes(runner: OnPolicyRunner, loaded: dict[str, Any], name: str, exact: bool) -> None:
    """One line each on stderr where a resume does not continue the killed run bit for bit: no env state in the
    checkpoint (new episodes); a CUDA run (its kernels need not reproduce bit for bit; an older checkpoint has no
    CUDA random state)."""
    if not exact:
        print(f"note: {name} holds no exact env state; the resumed run starts new episodes", file=sys.stderr)
    if torch.device(runner.device).type != "cuda":
        return
    what = ("with the checkpoint's CUDA random state" if "rng_cuda" in loaded
            else "without a CUDA random state in the checkpoint (new action noise)")
    print(f"note: resumed on {runner.device} {what}; CUDA kernels need not reproduce bit for bit, so the run "
          "continues as the killed one would to rounding, not bit for bit as on the CPU", file=sys.stderr)
