"""Training on a GPU (issue 51), checked on every device this machine has: CPU always, CUDA where torch sees it.

The device logic itself is checked on the CPU too: a tensor moved to the ``meta`` device stands for one left on the
wrong device, a config that says ``device: cuda`` for a run trained on a GPU. The tests marked CUDA skip without one.
``tools/gpu_check.py`` runs the same checks (:mod:`pathrl.train.device_check`) from a bare copy of the package.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
import yaml
from tensordict import TensorDict
from torch import nn

from pathrl.envs.device import (
    EVAL_DEVICE,
    DeviceError,
    check_run_device,
    native_note,
    off_device,
    resolve_device,
    same_device,
)
from pathrl.envs.registry import EVAL_ENV, EnvRequest, make_env
from pathrl.envs.state import restore, snapshot
from pathrl.models import model_dir, model_ref
from pathrl.policy.residual import ControllerObs
from pathrl.train import device_check as dc
from pathrl.train import placement

ROOT = Path(__file__).resolve().parents[1]
#: The smallest shipped model with weights (296 kB): a distilled student on the analytic ball, taught by the tray
#: controller, so its runs have a feedback part and a controller with state.
MODEL = model_dir("iiwa7_ball_balancing_distill")
DEVICES = dc.available_devices()
CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device")
BALL = {"name": "ball_on_plate", "feedback": "ball_on_plate", "backend": "pybullet"}


# ------------------------------------------------------------------------------------------ device names, refusals
@pytest.mark.parametrize("bad", ["cdua", "gpu", "CPU", "cuda:", "cuda:-1", "cuda:0x", "cpu cuda", "mps"])
def test_misspelt_devices_are_refused(bad):
    with pytest.raises(DeviceError, match="expected cpu, cuda or cuda:N"):
        resolve_device(bad)


def test_devices_that_do_not_exist_are_refused():
    assert resolve_device("cpu") == torch.device("cpu")
    count = torch.cuda.device_count() if torch.cuda.is_available() else 0
    with pytest.raises(DeviceError, match=f"device=cuda:{max(count, 7)} but"):
        resolve_device(f"cuda:{max(count, 7)}")
    if count == 0:
        with pytest.raises(DeviceError, match="no CUDA device"):
            resolve_device("cuda")
    else:
        assert resolve_device("cuda").type == "cuda" and resolve_device(f"cuda:{count - 1}").index == count - 1


@pytest.mark.parametrize("task", [BALL, {**BALL, "name": "standing", "feedback": "standing"},
                                  {**BALL, "name": "trueadapt_on_plate", "adapt": {"mode": "on_plate"}}])
def test_pybullet_tasks_train_on_the_cpu_only(task):
    with pytest.raises(DeviceError, match=f"task {task['name']} simulates in PyBullet, on the CPU only"):
        check_run_device({"device": "cuda:0", "task": task})  # refused whether or not there is a GPU
    assert check_run_device({"device": "cpu", "task": task}) == torch.device("cpu")
    assert check_run_device({"device": "cpu", "task": {**task, "backend": "analytic"}}) == torch.device("cpu")


def test_pybullet_feedback_is_refused_off_the_cpu_before_any_scene_is_built():
    from pathrl.envs.registry import make_feedback
    from pathrl.robot.external import load_robot_by_name

    cfg = {"task": BALL, "env": {"control_rate": 240.0}, "device": "cpu"}
    with pytest.raises(DeviceError, match="PyBullet"):
        make_feedback(cfg, load_robot_by_name("iiwa7"), 2, 0, device="cuda")


def test_a_trueadapt_env_in_pybullet_is_refused_off_the_cpu_before_its_data_is_read(tmp_path):
    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.repro import trueadapt as adapt
    from pathrl.runs import load_run

    cfg = load_run(model_dir(adapt.REALTIME_MODEL))[0]
    cfg["task"] = {**cfg["task"], "backend": "pybullet"}
    with pytest.raises(DeviceError, match="simulates in PyBullet, on the CPU only"):
        build_trueadapt_env(cfg, "test", 2, str(tmp_path / "no_dataset"), 0, device="cuda")


def test_same_device():
    assert same_device("cpu", torch.device("cpu")) and not same_device("cpu", "meta")
    assert not same_device(torch.device("cpu"), "cuda:0")


@CUDA
def test_cuda_and_its_index_are_the_same_device():
    assert same_device("cuda", f"cuda:{torch.cuda.current_device()}")


# ------------------------------------------------------------------------------------------- the walker
def test_off_device_looks_into_containers_modules_and_tensordicts():
    meta = torch.zeros(2, device="meta")
    root = {"ok": [torch.zeros(2), (torch.zeros(1),)], "bad": [meta], "td": TensorDict({"x": meta}, batch_size=[2]),
            "net": nn.Linear(2, 2).to("meta"), "gen": torch.Generator()}
    found = off_device(root, "cpu", "root")
    assert found == ["root['bad'][0] (meta)", "root['net'].bias (meta)", "root['net'].weight (meta)",
                     "root['td']['x'] (meta)"]
    assert off_device(root, "meta", "root") == ["root['gen'] (cpu)", "root['ok'][0] (cpu)", "root['ok'][1][0] (cpu)"]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    from pathrl.dataset.synthetic import write_synthetic

    return write_synthetic(tmp_path_factory.mktemp("device") / "iiwa7")


@pytest.mark.parametrize("device", DEVICES)
def test_the_walker_finds_a_tensor_off_the_env_device(device, dataset):
    r = dc.walker_finds_misplaced(MODEL, dataset, device)
    assert r["ok"], r
    assert len(r["found"]) == 3  # a state tensor, a dict entry, the ball's


# ------------------------------------------------------------------------------------------- restore onto the device
def _captured(obj, state, path="env"):
    """(name, tensor) of every entry of `obj` a snapshot `state` holds (tensors, dicts of tensors, parts)."""
    for name, v in state.items():
        cur = getattr(obj, name)
        if isinstance(v, torch.Tensor):
            yield f"{path}.{name}", cur
        elif "__part__" in v:
            yield from _captured(cur, v["__part__"], f"{path}.{name}")
        elif "__generator__" not in v:
            yield from ((f"{path}.{name}[{k!r}]", t) for k, t in cur.items())


def _to_meta(obj, state):
    """Move every entry of `obj` that `state` holds to the ``meta`` device (an env built on another device)."""
    if isinstance(getattr(obj, "device", None), torch.device):
        obj.device = torch.device("meta")
    for name, v in state.items():
        cur = getattr(obj, name)
        if isinstance(v, torch.Tensor):
            setattr(obj, name, cur.to("meta"))
        elif "__part__" in v:
            _to_meta(cur, v["__part__"])
        elif "__generator__" not in v:
            setattr(obj, name, {k: t.to("meta") for k, t in cur.items()})


def test_restore_puts_every_tensor_on_the_env_device(dataset):
    """A checkpoint loads to the CPU; the env it restores is elsewhere: dicts of tensors (the episode rewards) and
    the ball's state too must land on the env's device."""
    cfg, _ = dc.model_cfg(MODEL)
    env = make_env(cfg, EnvRequest(num_envs=4, dataset_path=str(dataset), backend="analytic"))
    state = snapshot(env)
    assert "ep_reward" in state and "feedback" in state
    _to_meta(env, state)
    restore(env, state)
    entries = dict(_captured(env, state))
    assert "env.ep_reward['path_length']" in entries and "env.feedback.xy" in entries
    assert {n: t.device.type for n, t in entries.items() if t.device.type != "meta"} == {}


def test_controller_state_goes_to_the_controllers_device():
    controller = SimpleNamespace(plan=torch.zeros(3, device="meta"))
    wrapper = ControllerObs(SimpleNamespace(device=torch.device("meta")), controller, "teacher")
    wrapper.load_state_dict({"controller": {"plan": torch.ones(3)}, "label": torch.ones(3, 2)})
    assert controller.plan.device.type == "meta" and wrapper._label.device.type == "meta"
    with pytest.raises(ValueError, match="not a tensor of this controller"):
        wrapper.load_state_dict({"controller": {"nope": torch.ones(1)}, "label": None})


def test_a_cuda_runs_checkpoint_resumes_onto_its_device(dataset, tmp_path, monkeypatch):
    """PathRLRunner.save and restore_streams of a run on ``cuda:0`` (the env and the teacher's plan standing on
    ``meta``): the CUDA random state is saved and set again, and the env's tensors, dicts of tensors, ball and the
    controller's plan and label, loaded to the CPU, all land back on the env's device."""
    from pathrl.runs import make_controller
    from pathrl.storage import load_checkpoint
    from pathrl.train.distill import TeacherLabels
    from pathrl.train.runner import PathRLRunner

    cfg, _ = dc.model_cfg(MODEL)
    env = make_env(cfg, EnvRequest(num_envs=4, dataset_path=str(dataset), backend="analytic"))
    wrapper = TeacherLabels(env, make_controller(cfg["teacher"], env))
    wrapper.get_observations()
    wrapper.step(torch.zeros(env.num_envs, env.num_actions))  # a plan in progress, a label of the new state
    rng_cuda, set_calls = torch.arange(16, dtype=torch.uint8), []
    monkeypatch.setattr(torch.cuda, "get_rng_state", lambda device="cuda": rng_cuda.clone())
    monkeypatch.setattr(torch.cuda, "set_rng_state", lambda state, device="cuda": set_calls.append((state, device)))
    logger = SimpleNamespace(writer=None, save_model=lambda path, it: None)
    runner = SimpleNamespace(env=wrapper, device="cuda:0", logger=logger, _summary=None, current_learning_iteration=3,
                             alg=SimpleNamespace(save=lambda: {"student_state_dict": {}}))
    PathRLRunner.save(runner, str(tmp_path / "model_3.pt"))
    loaded = load_checkpoint(tmp_path / "model_3.pt")
    assert torch.equal(loaded["rng_cuda"], rng_cuda) and loaded["controller_state"]["label"] is not None

    _to_meta(wrapper, loaded["env_state"])  # the snapshot of the wrapper: its env, the env's parts, the label
    controller = wrapper.controller
    for name in loaded["controller_state"]["controller"]:
        setattr(controller, name, getattr(controller, name).to("meta"))
    assert PathRLRunner.restore_streams(runner, loaded)  # the analytic ball: an exact resume
    assert len(set_calls) == 1 and torch.equal(set_calls[0][0], rng_cuda) and set_calls[0][1] == "cuda:0"
    entries = dict(_captured(wrapper, loaded["env_state"]))
    entries.update({f"controller.{n}": getattr(controller, n) for n in loaded["controller_state"]["controller"]})
    entries["label"] = wrapper._label
    assert len(entries) > 20 and {n for n, t in entries.items() if t.device.type != "meta"} == set()


# ------------------------------------------------------------------------------------------- start-up lines
def test_native_kernels_off_on_a_gpu_is_said_once():
    assert native_note("cpu", True, True) is None and native_note("cuda", False, True) is None
    assert native_note("cuda:0", True, False) is None
    assert "torch code computes the limits" in native_note("cuda:0", True, True)


def test_the_cpu_bfloat16_check_runs_for_cpu_runs_only(monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(placement, "bfloat16_warning", lambda agent: calls.append(agent) or "slow")
    monkeypatch.setattr(placement.native, "available", lambda: True)
    placement.start_notes({"device": "cuda", "agent": {}})
    assert calls == [] and capsys.readouterr().err.count("\n") == 1  # the native-kernel note only
    placement.start_notes({"device": "cpu", "agent": {}})
    assert len(calls) == 1 and "warning: slow" in capsys.readouterr().err


def test_bfloat16_on_a_gpu_without_it_is_said(monkeypatch):
    agent = {"actor": {"class_name": "pathrl.train.models:MixedPrecisionMLPModel", "hidden_dtype": "bfloat16"},
             "critic": {"class_name": "pathrl.train.models:MixedPrecisionMLPModel", "hidden_dtype": "float32"}}
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda including_emulation=True: False)
    monkeypatch.setattr(torch.cuda, "get_device_name", lambda device=None: "Tesla T4")
    line = placement.gpu_bfloat16_warning(agent, torch.device("cuda:0"))
    assert line.startswith("Tesla T4 has no native bfloat16") and line.endswith(
        "add agent.actor.hidden_dtype=float32 for a faster run")
    assert placement.gpu_bfloat16_warning(agent, torch.device("cpu")) is None
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", lambda including_emulation=True: True)
    assert placement.gpu_bfloat16_warning(agent, torch.device("cuda:0")) is None


def test_a_cuda_resume_says_it_is_not_bit_exact(capsys):
    runner = SimpleNamespace(device="cuda:0")
    placement.resume_notes(runner, {"rng_cuda": torch.zeros(1)}, "model_3.pt", True)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "CUDA random state" in err[0] and "not bit for bit" in err[0]
    placement.resume_notes(runner, {}, "model_3.pt", True)
    assert "new action noise" in capsys.readouterr().err
    placement.resume_notes(SimpleNamespace(device="cpu"), {}, "model_3.pt", True)
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------------------------------------- on every device
@pytest.mark.parametrize("device", DEVICES)
def test_env_steps_alike_on_the_cpu_and_on_the_device(device, dataset):
    """The same start states and actions: the CPU's native limit code and `device`'s torch code agree."""
    r = dc.step_parity(MODEL, dataset, device, num_envs=32, steps=12)
    assert r["ok"], r
    assert r["devices"] == ["cpu", device] and r["limits"] == ["native", "torch"]


@pytest.mark.parametrize("device", DEVICES)
def test_tiny_train_resume_and_evaluate(device, dataset, tmp_path):
    r = dc.train_resume_evaluate(MODEL, dataset, device, tmp_path, num_envs=16, steps_per_env=4, episodes=2)
    assert r["ok"], r
    assert r["off_device"] == [] and r["saved_device"] == device and r["eval_episodes"] == 2
    if device == "cpu":
        assert r["bit_exact"]  # a CPU resume continues bit for bit (also test_storage.py)


@CUDA
def test_a_cuda_checkpoint_holds_the_cuda_random_state(dataset, tmp_path, capsys):
    from pathrl.storage import load_checkpoint
    from pathrl.train.runner import train

    cfg = dc.tiny_run_cfg(MODEL, dataset, "cuda", tmp_path / "r", 1, num_envs=8, steps_per_env=2)
    train(cfg, tmp_path / "r")
    assert load_checkpoint(tmp_path / "r" / "model_0.pt")["rng_cuda"].dtype == torch.uint8
    assert "torch code computes the limits" in capsys.readouterr().err


def test_cli_device_check_does_not_need_cuda_for_a_cpu_run():
    assert check_run_device({"device": "cpu", "task": {"name": "tracking", "feedback": None}}).type == "cpu"


# ------------------------------------------------------------------------------------------- evaluation device
def _save_as_on_cuda(state: dict, path: Path) -> None:
    """:func:`~pathrl.storage.save_checkpoint` of `state` with every tensor tagged ``cuda:0`` in the file, as a GPU
    run writes it: a plain ``torch.load`` restores such tensors onto CUDA (and fails where there is none)."""
    from pathrl.storage import save_checkpoint

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(torch.serialization, "location_tag", lambda storage: "cuda:0")
        save_checkpoint(state, path)


def _gpu_trained(model: Path, dest: Path) -> Path:
    """A copy of `model` as a GPU run ships it: its config says ``cuda``, its checkpoint's tensors are CUDA's."""
    from pathrl.storage import load_checkpoint

    shutil.copytree(model, dest)
    cfg = yaml.safe_load((dest / "config.yaml").read_text())
    (dest / "config.yaml").write_text(yaml.safe_dump({**cfg, "device": "cuda"}, sort_keys=False))
    _save_as_on_cuda(load_checkpoint(model / "model.pt"), dest / "model.pt")
    return dest


def test_a_checkpoint_written_on_a_gpu_loads_on_the_cpu(tmp_path):
    """The simulation is faithful (without CUDA a plain load fails), and every pathrl loader maps to the CPU."""
    from pathrl.storage import load_checkpoint
    from pathrl.train.runner import PathRLRunner

    path = _gpu_trained(MODEL, tmp_path / "m") / "model.pt"
    if not torch.cuda.is_available():
        with pytest.raises(RuntimeError, match="CUDA"):
            torch.load(path, weights_only=True)
    loaded = load_checkpoint(path)
    weights = [t for k, v in loaded.items() if k.endswith("_state_dict") for t in v.values()]
    assert weights and {t.device.type for t in weights} == {"cpu"}
    runner = SimpleNamespace(load_state=lambda state, load_cfg, strict: state)  # what PathRLRunner.load hands on
    assert PathRLRunner.load(runner, str(path))["student_state_dict"].keys() == loaded["student_state_dict"].keys()


def test_a_gpu_trained_run_evaluates_on_the_evaluation_device(dataset, tmp_path):
    from pathrl.eval.evaluate import EvalOptions, evaluate

    assert EVAL_ENV["device"] == EVAL_DEVICE == "cpu"
    model = _gpu_trained(MODEL, tmp_path / "m")
    opts = EvalOptions(dataset_path=str(dataset), episodes=2, segments="full", out_dir=tmp_path / "e", num_envs=2,
                       record=False, progress=False, backend="analytic")
    m = evaluate(model, opts)  # the analytic ball was built on cfg's device
    assert m["episodes"] == 2 and m["limit_violations"] == 0


def test_the_follower_of_a_gpu_trained_run_builds_on_the_cpu(tmp_path):
    import numpy as np

    from pathrl.deploy import Follower

    follower = Follower.load(_gpu_trained(model_dir("iiwa7_random"), tmp_path / "m"))
    knots = 0.3 * np.sin(np.linspace(0.0, 3.0, 20)[:, None] + np.arange(follower.robot.path_dof))
    follower.reset(knots)
    assert follower.env.device.type == "cpu" and follower.decide().position.shape[1] == follower.robot.dof


def test_a_gpu_trained_trueadapt_policy_is_timed_on_the_cpu(tiny_trueadapt, tmp_path):
    from pathrl.eval import trueadapt_realtime as rt
    from pathrl.repro import trueadapt as adapt

    model = _gpu_trained(model_dir(adapt.REALTIME_MODEL), tmp_path / "m")
    r = rt.measure(model, str(tiny_trueadapt.path), decisions=3)  # builds the whole env: on the evaluation device
    assert r["decisions"] == 3


# ------------------------------------------------------------------------------------------- tools/gpu_check.py
BARE = ("pathrl", "conf", "pyproject.toml", "tools/gpu_check.py", model_ref(MODEL.name))


def test_gpu_check_dry_run_from_a_bare_copy(tmp_path):
    """The check ships on its own: the package, its configs, pyproject.toml, the script and one model (no tests/,
    datasets/, results/, other models); run from that copy with --dry-run (the whole flow on the CPU)."""
    copy = tmp_path / "copy"
    for rel in BARE:
        src, dest = ROOT / rel, copy / rel
        dest.parent.mkdir(parents=True, exist_ok=True)
        if src.is_symlink():
            dest.symlink_to(os.readlink(src))
        elif src.is_dir():
            shutil.copytree(src, dest, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy2(src, dest)
    size = sum(p.stat().st_size for p in copy.rglob("*") if p.is_file())
    assert size < 6e6, size
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(copy)}
    cmd = [sys.executable, "tools/gpu_check.py", "--dry-run", "--install", "--model", model_ref(MODEL.name)]
    r = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    assert "would run:" in r.stdout and "--index-url https://download.pytorch.org/whl/cu126" in r.stdout
    report = json.loads((copy / "bench" / "gpu.json").read_text())
    assert report["ok"] and report["dry_run"] and report["devices"] == DEVICES
    assert Path(report["machine"]["package"]) == (copy / "pathrl").resolve()
    assert report["dataset"].startswith("generated") and all(report["passed"].values()) and len(report["passed"]) >= 5
    assert {(r["device"], r["num_envs"]) for r in report["bench"]["env_steps"]} == {(d, 64) for d in DEVICES}
    assert {r["device"] for r in report["bench"]["ppo_iteration"]} == set(DEVICES)


def test_gpu_check_measures_the_issues_sizes_within_its_budget():
    """What a full (not --dry-run) check measures: env steps/s at 4096 and 65 536 envs, a PPO iteration at 4096."""
    gpu_check = _gpu_check()
    full = gpu_check.SIZES["full"]
    assert full["bench_envs"] == (4096, 65536) and full["ppo_envs"] == 4096 and gpu_check.BUDGET_S == 300.0


def _gpu_check():
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import gpu_check
    finally:
        sys.path.remove(str(ROOT / "tools"))
    return gpu_check


def test_gpu_check_packs_what_it_needs_to_ship(tmp_path, capsys):
    gpu_check = _gpu_check()
    assert tuple(BARE[:-1]) == gpu_check.SHIPPED
    out = tmp_path / "g.tar.gz"
    assert gpu_check.main(["--pack", str(out), "--model", str(MODEL)]) == 0
    import tarfile

    with tarfile.open(out) as tar:
        names = tar.getnames()
    top = {n.split("/", 2)[1] for n in names if n.count("/") >= 1}
    assert top == {"pathrl", "conf", "pyproject.toml", "tools", "models"}, top
    assert f"pathrl_gpu_check/models/{MODEL.name}/model.pt" in names and not any("__pycache__" in n for n in names)
    assert {n.split("/")[2] for n in names if n.startswith("pathrl_gpu_check/models/")} == {MODEL.name}
    assert out.stat().st_size < 5e6 and "tar xzf" in capsys.readouterr().out


def test_gpu_check_refuses_bad_arguments_and_a_machine_without_cuda(tmp_path, capsys):
    gpu_check = _gpu_check()
    with pytest.raises(SystemExit):
        gpu_check.main(["--model", str(tmp_path)])
    assert "not a model directory" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        gpu_check.main(["--model", str(MODEL), "--dataset", str(tmp_path)])
    assert "not a dataset directory" in capsys.readouterr().err
    if not torch.cuda.is_available():
        assert gpu_check.main(["--model", str(MODEL), "--out", str(tmp_path / "g.json")]) == 2
        assert "sees no CUDA device" in capsys.readouterr().err and not (tmp_path / "g.json").exists()
    from pathrl.repro import trueadapt as adapt

    assert gpu_check.main(["--model", str(model_dir(adapt.REALTIME_MODEL)), "--dry-run"]) == 2
    assert "the device checks take a policy of task tracking or ball_on_plate" in capsys.readouterr().err
    cmds = gpu_check.install_commands("cu128")
    assert cmds[0][-3:] == ["torch==2.13.0", "--index-url", "https://download.pytorch.org/whl/cu128"]
    assert not any(d.startswith("torch") for d in cmds[1][4:]) and "rsl-rl-lib==5.5.1" in cmds[1]
    assert gpu_check.install_commands("cu126", installed="2.13.0+cpu")[0][-1] == "--force-reinstall"
    assert "--force-reinstall" not in gpu_check.install_commands("cu126", installed="2.13.0+cu126")[0]
