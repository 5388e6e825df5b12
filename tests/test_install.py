"""Installability: a wheel of the package, installed into an empty directory, runs outside the checkout.

The wheel is built offline (``pip wheel --no-build-isolation --no-index``) from a copy of ``pyproject.toml``,
``README.md`` and ``pathrl/`` in a temporary directory, so the build leaves no ``build/`` or ``*.egg-info`` in
the checkout. The installed console scripts then run from a working directory outside the checkout with
``PYTHONPATH`` naming only the install: ``pathrl-train --help``, a tiny ``pathrl-dataset generate``, a 2-iteration
``pathrl-train`` and a 4-episode ``pathrl-eval``. Configs (``pathrl/conf``), the URDF and the native C sources must
come from the installed copy; relative data / run / result paths resolve against the working directory.
Deselect with ``-m "not install"``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.install

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


def _pip(*args: str, cwd: Path) -> None:
    r = subprocess.run([PY, "-m", "pip", *args], capture_output=True, text=True, cwd=cwd, timeout=180)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """Build the wheel offline and install it with ``--target``; returns the install directory."""
    tmp = tmp_path_factory.mktemp("install")
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(ROOT / "pathrl", src / "pathrl", ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.so"))
    _pip("wheel", str(src), "--no-deps", "--no-build-isolation", "--no-index", "-q", "-w", str(tmp / "wheel"), cwd=tmp)
    wheels = list((tmp / "wheel").glob("pathrl-*.whl"))
    assert len(wheels) == 1, wheels
    site = tmp / "site"
    _pip("install", "--no-deps", "--no-index", "-q", "--target", str(site), str(wheels[0]), cwd=tmp)
    return site


def test_installed_copy_trains_and_evaluates_outside_checkout(installed, tmp_path):
    work = tmp_path / "work"
    work.mkdir()
    assert not work.resolve().is_relative_to(ROOT)
    cache = tmp_path / "cache"  # a fresh native build from the installed C sources
    env = dict(os.environ, PYTHONPATH=str(installed), OMP_NUM_THREADS="1", PATHRL_CACHE_DIR=str(cache))
    scripts = installed / "bin"

    def run(*cmd: str) -> subprocess.CompletedProcess:
        r = subprocess.run(list(cmd), capture_output=True, text=True, cwd=work, env=env, timeout=180)
        assert r.returncode == 0, f"{cmd[:2]}: {r.stderr[-3000:]}"
        return r

    where = run(PY, "-c", "import pathrl, pathrl.config.paths as p; print(pathrl.__file__); print(p.CONF_DIR)")
    module, conf = (Path(line) for line in where.stdout.split())
    assert module.is_relative_to(installed) and conf == installed / "pathrl" / "conf"
    assert (conf / "train.yaml").is_file() and (conf / "hydra" / "launcher" / "local.yaml").is_file()

    # Hydra's help composes train.yaml and lists the config groups from the installed conf/
    out = run(str(scripts / "pathrl-train"), "--help").stdout
    assert "== Configuration groups ==" in out and "robot: armar4, armar4_legs, armar6, iiwa7" in out
    assert "urdf: pathrl:iiwa7.urdf" in out

    run(str(scripts / "pathrl-dataset"), "generate", "robot=iiwa7", "dataset=random", "dataset.num_train=4",
        "dataset.num_test=4", "dataset.path=datasets/iiwa7/tiny", "workers=1")
    assert (work / "datasets" / "iiwa7" / "tiny").is_dir()

    out = run(str(scripts / "pathrl-train"), "dataset.path=datasets/iiwa7/tiny", "run_dir=runs/tiny", "iterations=2",
              "env.num_envs=8", "agent.num_steps_per_env=8", "compile_limits=false", "threads=1").stdout
    assert "done: 2 iterations, 128 env steps" in out
    summary = json.loads((work / "runs" / "tiny" / "summary.json").read_text())
    assert summary["iterations"] == 2 and summary["env_steps"] == 2 * 8 * 8
    if shutil.which(os.environ.get("CC", "cc")):
        assert list(cache.glob("pathrl_native_*.so")), "native library not built from the installed sources"

    run(str(scripts / "pathrl-eval"), "run_dir=runs/tiny", "compile_limits=false", "episodes=4",
        "out=results/tiny_eval", "segments=full")
    metrics = json.loads((work / "results" / "tiny_eval" / "metrics.json").read_text())
    assert metrics["episodes"] == 4 and len(metrics["per_episode"]) == 4 and metrics["limit_violations"] == 0


def test_installed_copy_reads_the_table_rows(installed, tmp_path):
    """pathrl.repro.tables reads its rows from the installed sweeps/ (package data), and a table's sweep composes."""
    env = dict(os.environ, PYTHONPATH=str(installed), OMP_NUM_THREADS="1")
    code = ("import pathrl.repro.tables as t; print(t.SWEEPS_DIR); print(len(t.ROWS), len(t.WARM_STARTS), "
            "','.join(t.SWEEPS['table_II'].train))")
    r = subprocess.run([PY, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    from pathrl.repro.tables import ROWS, SWEEPS, WARM_STARTS  # the checkout's, for comparison

    assert r.stdout.splitlines() == [str(installed / "pathrl" / "sweeps"),
                                     f"{len(ROWS)} {len(WARM_STARTS)} {','.join(SWEEPS['table_II'].train)}"]
    out = subprocess.run([str(installed / "bin" / "pathrl-train"), "+sweep=table_II", "--cfg", "hydra",
                          "--package", "hydra.sweeper"], capture_output=True, text=True, cwd=tmp_path, env=env,
                         timeout=120)
    assert out.returncode == 0 and "iiwa7_random_length_lt_deviation" in out.stdout, out.stderr[-3000:]


def test_installed_copy_reads_the_papers_values(installed, tmp_path):
    """The papers' published values (pathrl/config/paper/*.yaml) are package data: read from the installed copy."""
    env = dict(os.environ, PYTHONPATH=str(installed), OMP_NUM_THREADS="1")
    code = ("from pathrl.config import paper; print(paper.DIR); "
            "print(*(len(paper.load(n).tables) for n in paper.PAPERS)); "
            "from pathrl.industrial.timing import PAPER_EXECUTION_S; print(PAPER_EXECUTION_S)")
    r = subprocess.run([PY, "-c", code], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    from pathrl.config import paper  # the checkout's, for comparison

    tables = " ".join(str(len(paper.load(n).tables)) for n in paper.PAPERS)
    assert r.stdout.splitlines() == [str(installed / "pathrl" / "config" / "paper"), tables, "12.0"]
