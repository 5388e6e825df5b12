"""GPU check: does pathrl train on this machine's GPU, correctly and how fast? One script, a 5-minute budget on one GPU.

    python tools/gpu_check.py --install --model models/tracking/iiwa7_ball_balancing_distill  # first run on a GPU
    python tools/gpu_check.py --model DIR [--dataset DIR] [--out bench/gpu.json]
    python tools/gpu_check.py --dry-run --model DIR                                    # the whole flow, CPU, tiny
    python tools/gpu_check.py --pack gpu_check.tar.gz --model DIR    # the copy to ship to a GPU machine, and stop

It needs only a copy of ``pathrl/``, ``conf/``, ``pyproject.toml``, this file and one shipped model (about 2 MB; not
the checkout's ``datasets/``, ``results/`` or other models): the package is imported from the copy this file sits in.
``--install`` first installs torch 2.13.0 built for CUDA (``--cuda``, default cu126, from the PyTorch index) and
pathrl's other dependencies from ``pyproject.toml``. Without ``--dataset`` a tiny synthetic dataset of the model's
robot is written to a temp dir.

Checks (the functions ``tests/test_device.py`` runs, :mod:`pathrl.train.device_check`), on the CPU and on CUDA:
bad devices refused in one line; the walker finds a tensor off the env's device; the model's env steps alike on the
CPU and on the GPU from the same start states; a tiny run trains, resumes (every tensor back on the GPU) and
evaluates on the evaluation device. Speed: env steps/s of plain path tracking at 4096 and 65 536 envs and one PPO
iteration (4096 envs x 16 steps) on the CPU and on CUDA. Writes ``--out`` (default ``bench/gpu.json`` next to
``tools/``); exit code 0 when every check passed, 1 when one failed, 2 for bad arguments or no GPU.
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
TORCH = "torch==2.13.0"
TORCH_INDEX = "https://download.pytorch.org/whl/{cuda}"
BUDGET_S = 300.0

#: Sizes of a full check and of a dry run (CPU, seconds).
SIZES = {
    "full": {"parity_envs": 256, "parity_steps": 30, "train_envs": 64, "train_steps": 8, "episodes": 4,
             "bench_envs": (4096, 65536), "bench_s": 3.0, "warmup": 3, "ppo_envs": 4096},
    "dry": {"parity_envs": 16, "parity_steps": 3, "train_envs": 16, "train_steps": 4, "episodes": 2,
            "bench_envs": (64,), "bench_s": 0.0, "warmup": 1, "ppo_envs": 64},
}


def _installed_torch() -> str | None:
    """The installed torch's version (``2.13.0+cpu``), read without importing it; None if there is none."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("torch")
    except PackageNotFoundError:
        return None


def install_commands(cuda: str, root: Path = ROOT, installed: str | None = None) -> list[list[str]]:
    """The pip commands of ``--install``: torch 2.13.0 for `cuda` (e.g. ``cu126``) from the PyTorch index (over an
    `installed` CPU build: reinstalled, pip would take ``2.13.0+cpu`` for 2.13.0), then the other dependencies of
    ``root/pyproject.toml`` (torch already satisfied, so pip keeps the CUDA build)."""
    deps = tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
    rest = [d for d in deps if not d.replace(" ", "").startswith(("torch=", "torch>", "torch<", "torch~"))]
    pip = [sys.executable, "-m", "pip", "install"]
    force = ["--force-reinstall"] if installed is not None and installed.endswith("+cpu") else []
    return [[*pip, TORCH, "--index-url", TORCH_INDEX.format(cuda=cuda), *force], [*pip, *rest]]


#: What a copy of the check holds, besides the model (paths relative to the checkout).
SHIPPED = ("pathrl", "conf", "pyproject.toml", "tools/gpu_check.py")


def pack(out: Path, model: Path, root: Path = ROOT) -> list[str]:
    """Write the check's copy as the tarball `out`: :data:`SHIPPED` and `model` (as ``models/<name>``), without
    ``__pycache__``; returns its member names."""
    import tarfile

    def keep(info: tarfile.TarInfo) -> tarfile.TarInfo | None:
        return None if "__pycache__" in Path(info.name).parts else info

    out.parent.mkdir(parents=True, exist_ok=True)
    with tarfile.open(out, "w:gz") as tar:
        for rel in SHIPPED:
            tar.add(root / rel, arcname=f"pathrl_gpu_check/{rel}", filter=keep)
        tar.add(model, arcname=f"pathrl_gpu_check/models/{model.resolve().name}", filter=keep)
    with tarfile.open(out) as tar:
        return tar.getnames()


def _args(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", type=Path, required=True, help="a shipped model directory (config.yaml + model.pt)")
    ap.add_argument("--dataset", type=Path, default=None, help="a dataset directory of the model's robot (train and "
                    "test splits); default: a tiny synthetic one")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "gpu.json")
    ap.add_argument("--dry-run", action="store_true", help="the whole flow at tiny sizes; CUDA not required")
    ap.add_argument("--install", action="store_true", help="first pip install torch 2.13.0 for CUDA and the other "
                    "dependencies (with --dry-run: print the commands only)")
    ap.add_argument("--cuda", default="cu126", help="the CUDA build of torch for --install (the index's name)")
    ap.add_argument("--pack", type=Path, default=None, help="write the copy to ship (a .tar.gz of the package, "
                    "conf/, pyproject.toml, this script and --model) and stop")
    ap.add_argument("--threads", type=int, default=None, help="torch threads for the CPU rows (default: all cores; "
                    "--dry-run: 1)")
    args = ap.parse_args(argv)
    if not ((args.model / "config.yaml").is_file() and (args.model / "model.pt").is_file()):
        ap.error(f"--model {args.model}: not a model directory (config.yaml and model.pt)")
    if args.dataset is not None and not (args.dataset / "dataset.json").is_file():
        ap.error(f"--dataset {args.dataset}: not a dataset directory (no dataset.json)")
    if args.threads is not None and args.threads < 1:
        ap.error(f"--threads must be >= 1, got {args.threads}")
    return args


def _install(args: argparse.Namespace) -> None:
    """Run (or, in a dry run, print) the ``--install`` commands; a failed one ends the check (exit 2)."""
    for cmd in install_commands(args.cuda, installed=_installed_torch()):
        print(("would run: " if args.dry_run else "running: ") + shlex.join(cmd), flush=True)
        if not args.dry_run and subprocess.run(cmd).returncode != 0:
            print(f"error: {' '.join(cmd[:6])} failed", file=sys.stderr)
            raise SystemExit(2)


def _machine() -> dict[str, Any]:
    """Versions and the devices of this machine."""
    import torch

    import pathrl

    gpu = None
    if torch.cuda.is_available():
        p = torch.cuda.get_device_properties(0)
        gpu = {"name": p.name, "count": torch.cuda.device_count(), "memory_gb": round(p.total_memory / 2**30, 1),
               "capability": f"{p.major}.{p.minor}", "bf16_native": torch.cuda.is_bf16_supported(False)}
    return {"host": platform.node(), "python": platform.python_version(), "torch": torch.__version__,
            "torch_cuda": torch.version.cuda, "gpu": gpu, "cpu": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "package": str(Path(pathrl.__file__).resolve().parent)}


def _guarded(fn, *args) -> dict[str, Any]:
    """``fn(*args)``, or ``{"ok": False, "error": ...}`` if it raised: one failing check (or a GPU out of memory)
    does not end the others."""
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001 - recorded in the report
        first = (str(exc).strip().splitlines() or [""])[0][:300]
        return {"ok": False, "error": f"{type(exc).__name__}: {first}"}


def _checks(model: Path, dataset: Path, devices: list[str], size: dict, work: Path) -> dict[str, Any]:
    """The device checks (:mod:`pathrl.train.device_check`) on every device of `devices`."""
    from pathrl.train import device_check as dc

    other = devices[-1]  # cuda where there is one; a CPU-only dry run compares the CPU's two limit codes
    out: dict[str, Any] = {"refusals": _guarded(dc.refusals)}
    out["walker"] = {d: _guarded(dc.walker_finds_misplaced, model, dataset, d) for d in devices}
    out["parity"] = _guarded(dc.step_parity, model, dataset, other, size["parity_envs"], size["parity_steps"])
    out["train_resume_evaluate"] = {d: _guarded(dc.train_resume_evaluate, model, dataset, d, work / d,
                                                size["train_envs"], size["train_steps"], size["episodes"])
                                    for d in devices}
    return out


def _bench(model: Path, dataset: Path, devices: list[str], size: dict, threads: int, dry: bool) -> dict[str, Any]:
    """Env steps/s and one PPO iteration of plain path tracking on every device of `devices`."""
    import torch

    from pathrl.policy.models import BFLOAT16_EMULATED, bfloat16_slowdown
    from pathrl.train import device_check as dc

    steps, ppo = [], []
    for d in devices:
        torch.set_num_threads(threads)
        cfg = dc.tracking_cfg(model, dataset, d)
        steps += [{"device": d, "num_envs": n, **_guarded(dc.env_steps_per_s, cfg, n, size["bench_s"], size["warmup"])}
                  for n in size["bench_envs"]]
        if d == "cpu":
            native_bf16 = not dry and bfloat16_slowdown() <= BFLOAT16_EMULATED
            dtypes = ["bfloat16"] if native_bf16 else ["float32"]
        else:
            dtypes = ["float32", *(["bfloat16"] if torch.cuda.is_bf16_supported() else [])]  # emulated: slow, shown
        ppo += [{"device": d, "num_envs": size["ppo_envs"], "hidden_dtype": dt,
                 **_guarded(dc.ppo_iteration, cfg, size["ppo_envs"], dt)} for dt in dtypes]
    return {"env_steps": steps, "ppo_iteration": ppo}


def _dataset(args: argparse.Namespace, work: Path) -> tuple[Path, str]:
    """(dataset directory, how it came): ``--dataset``, or a tiny synthetic one of the model's robot."""
    if args.dataset is not None:
        return args.dataset, str(args.dataset)
    import yaml

    from pathrl.dataset.synthetic import write_synthetic

    robot = yaml.safe_load((args.model / "config.yaml").read_text())["robot"]["name"]
    return write_synthetic(work / "dataset", robot), f"generated: 6 train, 3 test synthetic paths of {robot}"


def _summary(report: dict[str, Any]) -> str:
    """A few lines for the terminal."""
    gpu = report["machine"]["gpu"]
    over = f", over the {report['budget_s']:.0f} s budget" if report["check_s"] > report["budget_s"] else ""
    lines = [f"gpu_check: {'ok' if report['ok'] else 'FAILED'} in {report['check_s']:.0f} s{over} "
             f"({gpu['name'] if gpu else 'no GPU'}; torch {report['machine']['torch']})"]
    for name, ok in report["passed"].items():
        lines.append(f"  {'ok  ' if ok else 'FAIL'} {name}")
    for r in report["bench"]["env_steps"]:
        rate = f"{r['env_steps_per_s']:>12,.0f}" if "error" not in r else r["error"]
        lines.append(f"  env steps/s {r['device']:>6} {r['num_envs']:>6} envs: {rate}")
    for r in report["bench"]["ppo_iteration"]:
        took = (f"{r['s_per_iteration']:.3f} s ({r['samples_per_s']:,.0f} samples/s)" if "error" not in r
                else r["error"])
        lines.append(f"  PPO iteration {r['device']:>6} {r['num_envs']} envs {r['hidden_dtype']}: {took}")
    return "\n".join(lines)


def _passed(checks: dict[str, Any], bench: dict[str, Any]) -> dict[str, bool]:
    """Check name -> passed (the speed rows: measured without an error)."""
    out = {"refusals": bool(checks["refusals"]["ok"]), "parity": bool(checks["parity"]["ok"])}
    out.update({f"walker {d}": bool(r["ok"]) for d, r in checks["walker"].items()})
    out.update({f"train+resume+evaluate {d}": bool(r["ok"]) for d, r in checks["train_resume_evaluate"].items()})
    out["speed rows measured"] = not any("error" in r for rows in bench.values() for r in rows)
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the check; the exit code (0: every check passed, 1: one failed, 2: bad arguments or no GPU)."""
    t0 = time.perf_counter()
    args = _args(argv)
    if args.pack is not None:
        names = pack(args.pack, args.model)
        print(f"{args.pack}: {len(names)} files, {args.pack.stat().st_size / 1e6:.1f} MB; on the GPU machine: tar xzf "
              f"{args.pack.name} && cd pathrl_gpu_check && python tools/gpu_check.py --install --model "
              f"models/{args.model.resolve().name}")
        return 0
    if args.install:
        _install(args)
    if (ROOT / "pathrl").is_dir():
        sys.path.insert(0, str(ROOT))  # the copy this file is in, not another install
    import torch

    from pathrl.storage import write_json_atomic
    from pathrl.train.device_check import available_devices, model_cfg

    try:
        model_cfg(args.model)
    except ValueError as exc:
        print(f"error: --model {exc}", file=sys.stderr)
        return 2
    if not args.dry_run and not torch.cuda.is_available():
        print(f"error: torch {torch.__version__} sees no CUDA device; run with --install on a GPU machine, or "
              "--dry-run for the flow on the CPU", file=sys.stderr)
        return 2
    t_check = time.perf_counter()
    threads = args.threads or (1 if args.dry_run else os.cpu_count() or 1)
    torch.set_num_threads(threads)
    size, devices = SIZES["dry" if args.dry_run else "full"], available_devices()
    with tempfile.TemporaryDirectory(prefix="gpu_check_") as tmp:
        dataset, origin = _dataset(args, Path(tmp))
        checks = _checks(args.model, dataset, devices, size, Path(tmp))
        bench = _bench(args.model, dataset, devices, size, threads, args.dry_run)
    passed = _passed(checks, bench)
    report = {"dry_run": args.dry_run, "model": str(args.model), "dataset": origin, "devices": devices,
              "threads": threads, "machine": _machine(), "ok": all(passed.values()), "passed": passed,
              "checks": checks, "bench": bench, "wall_time_s": round(time.perf_counter() - t0, 1),
              "check_s": round(time.perf_counter() - t_check, 1), "budget_s": BUDGET_S}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out, report)
    print(_summary(report))
    print(f"-> {args.out}")
    return 0 if report["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
