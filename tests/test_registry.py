"""Contract of the task registry (pathrl.envs.registry): every registered task and every experiment in
conf/experiment/ builds an env through make_env that resets and steps; task names are checked in one place."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
import yaml

from pathrl.cli.common import CONF_DIR, compose, to_container
from pathrl.dataset.io import load_pathset
from pathrl.envs.registry import EVAL_ENV, TASKS, EnvRequest, check_task, get_task, make_env, task_cfg
from pathrl.envs.terminations import TerminationReason
from pathrl.models import model_dir, model_ref
from pathrl.paths.knots import KnotStrategy
from pathrl.robot.model import load_robot
from pathrl.schema import TrainAppCfg

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))
SAVED_RUNS = sorted(p.parent.name for p in (ROOT / "models").glob("*/*/config.yaml"))
STEPS = 3


@pytest.fixture(scope="module")
def tiny_trajectories(tiny_trueadapt) -> str:
    """The shared tiny TrueAdapt trajectory set (conftest) as a dataset path."""
    return str(tiny_trueadapt.path)


def _cfg(overrides: list[str]) -> dict:
    return to_container(compose("train", overrides, TrainAppCfg))


def _step(env, steps: int = STEPS) -> None:
    """Reset, then `steps` steps with zero actions: observations, rewards and dones keep their shapes."""
    try:
        obs = env.reset()["policy"]
        n = env.num_envs
        assert obs.shape == (n, env.num_obs) and bool(torch.isfinite(obs).all())
        for _ in range(steps):
            obs, rew, dones, extras = env.step(torch.zeros(n, env.num_actions))
            obs = obs["policy"]
            assert obs.shape == (n, env.num_obs) and bool(torch.isfinite(obs).all())
            assert rew.shape == (n,) and bool(torch.isfinite(rew).all())
            assert dones.shape == (n,) and dones.dtype == torch.bool and "time_outs" in extras
            if hasattr(env, "termination"):  # tracking, TrueAdapt: one reason per env, NONE exactly where not done
                assert env.termination.shape == (n,) and env.termination.dtype == torch.int8
                assert torch.equal(env.termination != TerminationReason.NONE, dones)
    finally:
        fb = getattr(env, "feedback", None) or getattr(env, "ball", None)
        if fb is not None:
            fb.close()


def test_every_task_config_is_registered():
    names = {yaml.safe_load(p.read_text())["name"]: p.stem for p in (CONF_DIR / "task").glob("*.yaml")}
    assert all(stem == name for name, stem in names.items())  # conf/task/<name>.yaml
    assert set(names) == set(TASKS)


def test_unknown_or_inconsistent_task_is_a_one_line_error():
    with pytest.raises(ValueError, match=r"^task\.name: unknown task 'juggling'; known: tracking, ball_on_plate, "
                                         r"standing, trueadapt_on_plate, trueadapt_in_place$"):
        get_task({"task": {"name": "juggling"}})
    with pytest.raises(ValueError, match=r"^task standing: task\.feedback must be 'standing', got 'ball_on_plate'$"):
        get_task({"task": {"name": "standing", "feedback": "ball_on_plate"}})
    with pytest.raises(ValueError, match="task.adapt must be set"):
        get_task({"task": {"name": "trueadapt_on_plate", "feedback": "ball_on_plate"}})
    assert get_task({}).name == "tracking"  # a config saved before tasks existed


@pytest.mark.parametrize("run", SAVED_RUNS)
def test_saved_runs_name_registered_tasks(run):
    cfg = yaml.safe_load((model_dir(run) / "config.yaml").read_text())
    if "robot" not in cfg:  # not a path-tracking run (the industrial TD3 models)
        pytest.skip(f"{model_ref(run)} is not a pathrl path-tracking run")
    assert get_task(cfg).name in TASKS


#: Tasks with a tiny dataset: the config overrides of a small env of each and its dataset fixture. The others
#: (standing: ARMAR-4 in PyBullet) are built by the experiments that use them (test_every_experiment_...).
TASK_RUNS = {
    "tracking": ([], "tiny_dataset"),
    "ball_on_plate": (["task=ball_on_plate"], "tiny_dataset"),
    "trueadapt_on_plate": (["+experiment=iiwa7_trueadapt_on_plate"], "tiny_trajectories"),
    "trueadapt_in_place": (["+experiment=iiwa7_trueadapt_in_place"], "tiny_trajectories"),
}


def _experiment_task(name: str) -> str:
    """The task an experiment selects (its ``override /task`` default; none: tracking), read without composing."""
    defaults = yaml.safe_load((CONF_DIR / "experiment" / f"{name}.yaml").read_text()).get("defaults") or []
    return next((d["override /task"] for d in defaults if isinstance(d, dict) and "override /task" in d), "tracking")


def test_every_task_is_built_here_or_by_an_experiment():
    by_experiments = {_experiment_task(name) for name in EXPERIMENTS}
    assert by_experiments <= set(TASKS) and set(TASKS) <= set(TASK_RUNS) | by_experiments
    assert get_task(_cfg(["+experiment=armar4_legs_balance_residual"])).name == _experiment_task(
        "armar4_legs_balance_residual") == "standing"  # the defaults are read as Hydra reads them


@pytest.mark.parametrize("name", list(TASK_RUNS))
def test_every_task_creates_and_steps(name, request):
    overrides, fixture = TASK_RUNS[name]
    cfg = _cfg([*overrides, f"dataset.path={request.getfixturevalue(fixture)}"])
    assert check_task(cfg).name == name
    env = make_env(cfg, EnvRequest("test", num_envs=2, seed=0))
    assert type(env).__name__ == ("TrueAdaptEnv" if TASKS[name].adapt else "PathTrackingEnv")
    _step(env)


_PATHS: dict[tuple, object] = {}  # test splits loaded once per (dataset, robot, knots): experiments share them


def _experiment_env(cfg: dict, request):
    """The experiment's env (2 envs; 1 PyBullet scene) on this checkout's data: the committed test split of its dataset
    (datasets/<robot>/<name>), or a tiny generated trajectory set for the TrueAdapt experiments; skips when the
    dataset is not in the checkout."""
    if get_task(cfg).adapt:
        data = request.getfixturevalue("tiny_trajectories")
        return make_env(cfg, EnvRequest("test", num_envs=2, seed=0, dataset_path=data))
    committed = ROOT / "datasets" / Path(cfg["dataset"]["path"]).relative_to("data")
    if not (committed / "dataset.json").is_file():
        pytest.skip(f"needs {cfg['dataset']['path']} (not in the checkout: generate it with pathrl-dataset)")
    robot = load_robot(cfg["robot"])
    key = (str(committed), robot.name, yaml.safe_dump(cfg["knots"]))
    if key not in _PATHS:
        _PATHS[key] = load_pathset(str(committed), "test", KnotStrategy.from_cfg(cfg["knots"]), robot=robot)
    pybullet = task_cfg(cfg)["backend"] == "pybullet" and get_task(cfg).feedback is not None
    req = EnvRequest("test", num_envs=1 if pybullet else 2, seed=0, paths=_PATHS[key], robot=robot)
    return make_env(cfg, req, **EVAL_ENV)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_every_experiment_creates_and_steps(name, request):
    cfg = _cfg([f"+experiment={name}", "task.workers=1"])
    check_task(cfg)
    _step(_experiment_env(cfg, request))


def test_standing_builds_on_the_analytic_model_and_defaults_to_pybullet(request):
    """``task=standing task.backend=analytic``: the tracking env with the batched standing model (training); the task's
    default stays PyBullet (evaluation)."""
    assert task_cfg(_cfg(["+experiment=armar4_legs_target_point_balancing"]))["backend"] == "pybullet"
    cfg = _cfg(["+experiment=armar4_legs_target_point_balancing", "task.backend=analytic"])
    env = _experiment_env(cfg, request)
    assert type(env).__name__ == "PathTrackingEnv" and type(env.feedback).__name__ == "AnalyticStanding"
    assert env.num_envs == 2
    _step(env)
