"""Every table row and sweep composes; the train CLI's multirun reports a failing job without stopping the others."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from pathrl.cli.common import CONF_DIR
from pathrl.cli.store import register
from pathrl.models import model_ref
from pathrl.repro.tables import SWEEPS as TABLES

EXPERIMENTS = sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))
SWEEPS = sorted(name for name, spec in TABLES.items() if spec.train)  # sweeps/<table>.yaml with a train list
BIN = Path(__import__("sys").executable).parent


def _compose(overrides, hydra_cfg=False):
    register()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("train", overrides=overrides, return_hydra_config=hydra_cfg)


#: Recipes for any robot (`robot=<name>` on the command line): named by what they do, not by a robot.
ANY_ROBOT = {"robot_track_distill"}


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_composes(name):
    cfg = _compose([f"+experiment={name}"])
    assert cfg.experiment == name
    assert cfg.run_dir == f"runs/{name}/seed0"
    from pathrl.repro.tables import PATH_ROBOT

    assert cfg.dataset.path == f"data/{PATH_ROBOT.get(cfg.robot.name, cfg.robot.name)}/{cfg.dataset.name}"
    assert (name in ANY_ROBOT or name.startswith(cfg.robot.name)) and cfg.iterations > 0
    if not cfg.task.adapt:  # a TrueAdapt task has its own reward (pathrl.envs.trueadapt_rewards)
        assert cfg.reward.terms.path_length.weight > 0


def test_experiment_values():
    assert _compose(["+experiment=iiwa7_random_knots5"]).knots.n_state == 5
    assert _compose(["+experiment=iiwa7_random_length_eq_deviation"]).reward.terms.path_length.weight == 2.0
    assert _compose(["+experiment=iiwa7_random"]).reward == _compose([]).reward  # Table I row = default config
    ball = _compose(["+experiment=iiwa7_ball_balancing"])
    assert (ball.env.segments, ball.knots.strategy, ball.knots.n_state) == ("full", "distance", 5)
    assert _compose(["+experiment=armar4_random"]).robot.name == "armar4"
    assert _compose(["+experiment=iiwa7_ball_balancing_tcp"]).env.tcp_obs is True
    assert _compose([]).env.tcp_obs is False


@pytest.mark.parametrize("name", SWEEPS)
def test_sweep_composes_with_existing_experiments(name):
    cfg = _compose([f"+sweep={name}"], hydra_cfg=True)
    exps = cfg.hydra.sweeper.params["+experiment"].split(",")
    assert tuple(exps) == TABLES[name].train  # the sweep runs the experiments of sweeps/<name>.yaml
    assert set(exps) <= set(EXPERIMENTS) and len(exps) >= 3
    assert cfg.hydra.launcher._target_.endswith("JoblibLauncher")
    assert cfg.hydra.launcher.n_jobs * cfg.threads <= 2  # respects the 2-core machine
    for e in exps:  # each job composes
        assert _compose([f"+sweep={name}", f"+experiment={e}"]).experiment == e


def test_slurm_launcher_composes():
    cfg = _compose(["+sweep=table_I", "hydra/launcher=slurm"], hydra_cfg=True)
    assert "submitit" in cfg.hydra.launcher._target_.lower()
    assert cfg.hydra.launcher.cpus_per_task >= 1


#: Launchers a sweep runs through: Hydra's own, joblib (conf/hydra/launcher/local.yaml), submitit's local
#: executor (the SLURM plugin's local twin) and Ray on a local head node bound to 127.0.0.1.
LAUNCHERS = {
    "basic": [],
    "joblib": ["hydra/launcher=local"],
    "submitit_local": ["hydra/launcher=submitit_local", "hydra.launcher.timeout_min=10",
                       "hydra.launcher.cpus_per_task=1"],
    "ray": ["hydra/launcher=ray_cluster", "+hydra.launcher.ray.init.num_cpus=2",
            "+hydra.launcher.ray.init._node_ip_address=127.0.0.1", "+hydra.launcher.ray.init.include_dashboard=false",
            "hydra.launcher.ray.remote.num_cpus=1"],
}


@pytest.mark.slow
@pytest.mark.parametrize("launcher", list(LAUNCHERS))
def test_multirun_failing_job_does_not_stop_the_others(launcher, tmp_path, tiny_dataset):
    """Two jobs, the first with a missing dataset: the second still trains; jobs.jsonl names the failure, the
    summary prints, the exit code is the number of failed jobs, and no traceback is shown."""
    plugin = {"submitit_local": "hydra_plugins.hydra_submitit_launcher", "ray": "hydra_plugins.hydra_ray_launcher"}
    if launcher in plugin:
        pytest.importorskip(plugin[launcher], reason=f"the {launcher} launcher plugin is not installed")
    sweep = tmp_path / "sweep"
    r = subprocess.run(
        [str(BIN / "pathrl-train"), "-m", f"dataset.path={tmp_path / 'missing'},{tiny_dataset}",
         "iterations=1", "env.num_envs=16", "agent.num_steps_per_env=4", "threads=1", "compile_limits=false",
         f"run_dir={tmp_path}/run_${{hydra:job.num}}", f"hydra.sweep.dir={sweep}", *LAUNCHERS[launcher]],
        cwd=tmp_path, capture_output=True, text=True, timeout=600)
    recs = sorted((json.loads(x) for x in (sweep / "jobs.jsonl").read_text().splitlines()), key=lambda x: x["job"])
    assert [x["status"] for x in recs] == ["failed", "ok"], r.stderr[-2000:]
    assert "dataset directory not found" in recs[0]["error"]
    assert (tmp_path / "run_1" / "summary.json").is_file()
    assert r.returncode == 1 and "sweep: 1/2 jobs finished" in r.stdout
    assert "Traceback" not in r.stdout + r.stderr


def test_warm_starts_match_the_experiments():
    """WARM_STARTS, read from the experiment files without Hydra, is what Hydra composes (defaults included)."""
    from pathrl.repro.tables import WARM_STARTS

    assert len(WARM_STARTS) >= 14
    for name in EXPERIMENTS:  # both ways: every warm start, and no init_from on the others
        expected = model_ref(WARM_STARTS[name]) if name in WARM_STARTS else None
        assert _compose([f"+experiment={name}"]).init_from == expected, name
