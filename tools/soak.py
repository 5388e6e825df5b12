"""Crash soak: kill -9 a tiny training at random moments, resume it each time, and check that nothing is lost.

    python tools/soak.py --kills 20 --out bench/soak.json

A reference run trains uninterrupted. The soak run trains the same config (same seed, same iteration count)
in a subprocess that is killed (SIGKILL) after a random delay, then resumed (``resume=true``), until it
finishes. Some kills also damage the newest checkpoint (truncate it to half), as a disk that failed mid-write
would. After each kill the tool records what the kill left (temp files: it hit a write) and checks:

- the checkpoint the resume will use is at most one save interval behind the last iteration in run.mcap;
- at the end, run.mcap reads with the plain ``mcap`` reader, holding every iteration exactly once;
- the final weights (actor and critic) equal the uninterrupted run's, bit for bit.

Exit 0 when every check passes, 1 otherwise; the JSON report names each kill.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import torch

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def train_cmd(dataset: Path, run_dir: Path, iterations: int, save_interval: int) -> list[str]:
    return [str(BIN / "pathrl-train"), f"dataset.path={dataset}", f"run_dir={run_dir}", f"iterations={iterations}",
            "env.num_envs=32", "agent.num_steps_per_env=8", f"agent.save_interval={save_interval}",
            "compile_limits=false", "threads=1", "resume=true"]


def logged_iterations(run_dir: Path) -> list[int]:
    """Iterations in run.mcap, read leniently (a killed writer leaves no footer)."""
    from pathrl.logging.mcap_io import iter_messages
    from pathrl.logging.schema import TRAIN_SCALARS

    path = run_dir / "run.mcap"
    if not path.exists():
        return []
    return [m["iteration"] for t, _, m in iter_messages(path) if t == TRAIN_SCALARS]


def plain_mcap_iterations(path: Path) -> list[int]:
    """Iterations in run.mcap read by the stock reader (needs a complete file: summary and footer)."""
    from mcap.reader import make_reader

    from pathrl.logging.schema import TRAIN_SCALARS

    with open(path, "rb") as f:
        return [json.loads(msg.data)["iteration"] for _, ch, msg in make_reader(f).iter_messages()
                if ch.topic == TRAIN_SCALARS]


def weights(ckpt: Path) -> dict[str, torch.Tensor]:
    from pathrl.storage import load_checkpoint

    s = load_checkpoint(ckpt)
    return {f"{k}.{n}": t for k in ("actor_state_dict", "critic_state_dict") for n, t in s[k].items()}


def run(args: argparse.Namespace) -> dict:
    from pathrl.dataset.synthetic import write_synthetic
    from pathrl.storage import checkpoint_iteration, latest_checkpoint, latest_valid_checkpoint

    rng = random.Random(args.seed)
    work = args.work
    work.mkdir(parents=True, exist_ok=True)
    dataset = work / "dataset"
    if not dataset.exists():
        write_synthetic(dataset)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    ref, soak = work / "reference", work / "soak"
    for d in (ref, soak):
        if d.exists():
            raise SystemExit(f"error: {d} exists; give an empty --work directory")
    t0 = time.perf_counter()
    r = subprocess.run(train_cmd(dataset, ref, args.iterations, args.save_interval), cwd=ROOT, env=env,
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"error: the reference run failed: {r.stderr.strip().splitlines()[-1]}")
    ref_s = time.perf_counter() - t0
    kills, failures = [], []
    legs = 0
    while True:
        legs += 1
        p = subprocess.Popen(train_cmd(dataset, soak, args.iterations, args.save_interval), cwd=ROOT, env=env,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if len(kills) < args.kills:
            delay = rng.uniform(args.min_delay, args.max_delay)
            try:
                p.wait(timeout=delay)
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGKILL)
                p.wait()
                tmp = [*soak.glob("*.tmp"), *soak.glob(".*.tmp")]
                rec = {"leg": legs, "after_s": round(delay, 2), "tmp_files": sorted(x.name for x in tmp)}
                logged = logged_iterations(soak)
                newest = latest_checkpoint(soak)
                if args.damage_every and (len(kills) + 1) % args.damage_every == 0 and newest is not None:
                    data = newest.read_bytes()
                    newest.write_bytes(data[: len(data) // 2])
                    rec["damaged"] = newest.name
                valid = latest_valid_checkpoint(soak, warn=False)
                rec["last_logged"] = logged[-1] if logged else None
                rec["resume_from"] = None if valid is None else checkpoint_iteration(valid)
                # a checkpoint is written after its iteration is logged, so the resume point may trail the log
                # by one save interval (two when the newest checkpoint was damaged on purpose)
                allowed = args.save_interval * (2 if "damaged" in rec else 1)
                behind = logged[-1] - (-1 if valid is None else checkpoint_iteration(valid)) if logged else 0
                rec["ok"] = behind <= allowed
                if not rec["ok"]:
                    failures.append(f"kill {len(kills) + 1}: resume point {rec['resume_from']} is more than "
                                    f"{allowed} behind the log ({logged[-1]})")
                kills.append(rec)
                continue
        _, err = p.communicate()
        if p.returncode != 0:
            failures.append(f"leg {legs}: exit {p.returncode}: {err.strip().splitlines()[-1] if err.strip() else ''}")
            break
        if len(kills) < args.kills:
            failures.append(f"the run finished after {len(kills)} of {args.kills} kills: raise --iterations")
        break
    final = f"model_{args.iterations - 1}.pt"
    result = {"kills": len(kills), "legs": legs, "iterations": args.iterations, "save_interval": args.save_interval,
              "reference_s": round(ref_s, 1), "kills_in_writes": sum(bool(k["tmp_files"]) for k in kills),
              "damaged_checkpoints": sum("damaged" in k for k in kills), "per_kill": kills}
    if not (soak / final).is_file():
        failures.append(f"the soak run has no {final}")
    else:
        a, b = weights(ref / final), weights(soak / final)
        result["weights_equal"] = a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
        if not result["weights_equal"]:
            failures.append("final weights differ from the uninterrupted run's")
        try:
            its = plain_mcap_iterations(soak / "run.mcap")
        except Exception as exc:  # the stock reader's errors vary by damage
            its = None
            failures.append(f"run.mcap does not read with the plain mcap reader: {exc}")
        result["log_every_iteration_once"] = its == list(range(args.iterations))
        if its is not None and not result["log_every_iteration_once"]:
            failures.append(f"run.mcap iterations are not 0..{args.iterations - 1} exactly once")
    result["failures"] = failures
    result["recovered"] = sum(k["ok"] for k in kills)  # kills after which the resume point was within an interval
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--iterations", type=int, default=2500)
    ap.add_argument("--save-interval", type=int, default=1)
    ap.add_argument("--min-delay", type=float, default=2.0, help="earliest kill after a leg starts (s)")
    ap.add_argument("--max-delay", type=float, default=10.0, help="latest kill after a leg starts (s)")
    ap.add_argument("--damage-every", type=int, default=4, help="truncate the newest checkpoint at every n-th kill")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", type=Path, default=None, help="empty work directory (default: a temp dir)")
    ap.add_argument("--out", type=Path, default=None, help="write the JSON report here")
    args = ap.parse_args(argv)
    if args.kills < 0 or args.iterations < 2 or args.save_interval < 1 or not 0 <= args.min_delay <= args.max_delay:
        print("error: need --kills >= 0, --iterations >= 2, --save-interval >= 1, 0 <= --min-delay <= --max-delay",
              file=sys.stderr)
        return 2
    if args.work is None:
        import tempfile

        args.work = Path(tempfile.mkdtemp(prefix="pathrl_soak_"))
    result = run(args)
    text = json.dumps(result, indent=2)
    if args.out:
        from pathrl.storage import atomic_write

        args.out.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(args.out, text)
    summary = {k: v for k, v in result.items() if k != "per_kill"}
    print(json.dumps(summary, indent=2))
    return 0 if not result["failures"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
