"""Checkpoints: digests, verification, fallback to the newest valid one; exact resume; leftovers; soak."""

import json
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import torch
from test_train import BIN, ROOT, run, scalars, train_cmd

from pathrl.models import model_dir
from pathrl.storage import (
    CheckpointError,
    atomic_write,
    clean_leftovers,
    content_digest,
    latest_valid_checkpoint,
    load_checkpoint,
    save_checkpoint,
)

STATE = {"actor_state_dict": {"w": torch.arange(600.0).reshape(20, 30), "b": torch.zeros(2, dtype=torch.bfloat16)},
         "iter": 7, "infos": {"wall_time_s": 1.5}}


def test_digest_covers_names_values_dtypes_and_shapes():
    d = content_digest(STATE)
    assert d == content_digest({k: STATE[k] for k in reversed(list(STATE))})  # key order does not matter
    changed = [
        {**STATE, "iter": 8},
        {**STATE, "actor_state_dict": {**STATE["actor_state_dict"], "w": torch.arange(600.0).reshape(30, 20)}},
        {**STATE, "actor_state_dict": {**STATE["actor_state_dict"], "w": torch.arange(600.0, dtype=torch.float64)
                                       .reshape(20, 30)}},
        {**STATE, "actor_state_dict": {"w2": STATE["actor_state_dict"]["w"], "b": STATE["actor_state_dict"]["b"]}},
    ]
    assert len({d, *(content_digest(s) for s in changed)}) == 1 + len(changed)


def _flip_tensor_bytes(path: Path, n: int = 64) -> None:
    """Flip `n` bytes in the middle of the largest tensor record of a torch zip file (not in its headers)."""
    with zipfile.ZipFile(path) as z:
        info = max((i for i in z.infolist() if "/data/" in i.filename), key=lambda i: i.file_size)
    raw = bytearray(path.read_bytes())
    name_len, extra_len = int.from_bytes(raw[info.header_offset + 26:info.header_offset + 28], "little"), \
        int.from_bytes(raw[info.header_offset + 28:info.header_offset + 30], "little")
    start = info.header_offset + 30 + name_len + extra_len + info.file_size // 2 - n // 2
    for i in range(start, start + n):
        raw[i] ^= 0xFF
    path.write_bytes(bytes(raw))


@pytest.mark.filterwarnings("ignore:Detected pickle protocol")
def test_save_load_roundtrip_and_every_kind_of_damage(tmp_path):
    p = tmp_path / "model_7.pt"
    save_checkpoint(STATE, p)
    back = load_checkpoint(p)
    assert "sha256" not in back and torch.equal(back["actor_state_dict"]["w"], STATE["actor_state_dict"]["w"])
    assert not list(tmp_path.glob("*.tmp"))
    _flip_tensor_bytes(p)
    with pytest.raises(CheckpointError, match="does not match its sha256"):
        load_checkpoint(p)
    p.write_bytes(b"")
    with pytest.raises(CheckpointError, match="unreadable checkpoint"):
        load_checkpoint(p)
    save_checkpoint(STATE, p)
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])  # truncated
    with pytest.raises(CheckpointError, match="unreadable checkpoint"):
        load_checkpoint(p)
    p.write_bytes(pickle.dumps(print))  # a pickle naming a callable: refused by weights_only, one line
    with pytest.raises(CheckpointError) as exc:
        load_checkpoint(p)
    assert "\n" not in str(exc.value)
    torch.save([1, 2], p)
    with pytest.raises(CheckpointError, match="not a pathrl checkpoint"):
        load_checkpoint(p)
    # a checkpoint from before digests existed loads unverified
    torch.save(STATE, p)
    assert load_checkpoint(p)["iter"] == 7


def test_newest_valid_checkpoint_and_leftovers(tmp_path):
    for k in (0, 1, 2):
        save_checkpoint({**STATE, "iter": k}, tmp_path / f"model_{k}.pt")
    (tmp_path / "model_2.pt").write_bytes(b"\0" * 10)
    assert latest_valid_checkpoint(tmp_path, warn=False).name == "model_1.pt"
    atomic_write(tmp_path / "a.json", "{}")
    (tmp_path / "model_3.pt.tmp").write_bytes(b"x")
    (tmp_path / ".run.mcap.tmp").write_bytes(b"x")
    removed = sorted(p.name for p in clean_leftovers(tmp_path))
    assert removed == [".run.mcap.tmp", "model_3.pt.tmp"] and (tmp_path / "a.json").read_text() == "{}"


def test_resume_equals_an_uninterrupted_run(tiny_dataset, tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert run(train_cmd(tiny_dataset, a, 4, "std_anneal=null")).returncode == 0
    assert run(train_cmd(tiny_dataset, b, 2, "std_anneal=null")).returncode == 0
    r = run(train_cmd(tiny_dataset, b, 4, "std_anneal=null", "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]
    sa, sb = load_checkpoint(a / "model_3.pt"), load_checkpoint(b / "model_3.pt")
    for key in ("actor_state_dict", "critic_state_dict", "rng_torch"):
        pa, pb = (sa[key], sb[key]) if key == "rng_torch" else (sa[key], sb[key])
        if isinstance(pa, dict):
            assert all(torch.equal(pa[n], pb[n]) for n in pa), key
        else:
            assert torch.equal(pa, pb)
    assert not torch.equal(sa["actor_state_dict"]["mlp.0.weight"],
                           load_checkpoint(a / "model_1.pt")["actor_state_dict"]["mlp.0.weight"])


def test_resume_falls_back_past_a_damaged_checkpoint(tiny_dataset, tmp_path):
    d = tmp_path / "run"
    assert run(train_cmd(tiny_dataset, d, 3)).returncode == 0
    (d / "model_2.pt").write_bytes((d / "model_2.pt").read_bytes()[:100])
    (d / "model_3.pt.tmp").write_bytes(b"half a checkpoint")
    r = run(train_cmd(tiny_dataset, d, 4, "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "skipping" in r.stderr and (d / "model_2.pt.damaged").is_file() and not (d / "model_3.pt.tmp").exists()
    assert [m["iteration"] for m in scalars(d)] == [0, 1, 2, 3]  # iteration 2 redone, logged once
    load_checkpoint(d / "model_2.pt")
    load_checkpoint(d / "model_3.pt")
    # every checkpoint damaged: a one-line error, not a silent fresh start
    for p in d.glob("model_*.pt"):
        p.write_bytes(b"")
    r = run(train_cmd(tiny_dataset, d, 5, "resume=true"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and lines[-1].startswith("error:") and "no checkpoint verifies" in lines[-1]


def test_evaluating_a_damaged_model_is_a_one_line_error(tmp_path):
    model = tmp_path / "model"
    model.mkdir()
    for name in ("config.yaml", "model.pt", "summary.json"):
        (model / name).write_bytes((model_dir("iiwa7_random") / name).read_bytes())
    _flip_tensor_bytes(model / "model.pt")
    r = run([str(BIN / "pathrl-eval"), f"run_dir={model}", "episodes=2", f"out={tmp_path / 'out'}",
             "dataset.path=datasets/iiwa7/random"])
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "sha256" in lines[0], r.stderr[-1000:]
    assert not (tmp_path / "out").exists()


def test_shipped_models_carry_a_digest():
    for p in sorted((ROOT / "models").glob("*/*/model.pt")):
        assert "sha256" in torch.load(p, weights_only=True, map_location="cpu"), p
        load_checkpoint(p)


@pytest.mark.slow
def test_soak_small(tmp_path):
    r = subprocess.run([sys.executable, "tools/soak.py", "--kills", "3", "--iterations", "150", "--max-delay", "6",
                        "--work", str(tmp_path / "w"), "--out", str(tmp_path / "soak.json")],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    rep = json.loads((tmp_path / "soak.json").read_text())
    assert r.returncode == 0, rep["failures"]
    assert rep["kills"] == 3 and rep["recovered"] == 3 and rep["weights_equal"] and rep["log_every_iteration_once"]
