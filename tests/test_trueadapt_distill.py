"""TrueAdapt distilled (conf/experiment/iiwa7_trueadapt_*_distill.yaml): a tiny DAgger run with the tray controller as
teacher lowers the behaviour loss, and its checkpoint acts on the policy observation alone."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from pathrl.cli.common import compose, to_container
from pathrl.logging.mcap_io import read_messages
from pathrl.schema import TrainAppCfg


def _cfg(experiment: str, dataset: Path, run_dir: Path, iterations: int) -> dict:
    return to_container(compose("train", [f"+experiment={experiment}", f"dataset.path={dataset}",
                                          f"iterations={iterations}", "env.num_envs=16", f"run_dir={run_dir}",
                                          "compile_limits=false", "threads=1"], TrainAppCfg))


@pytest.mark.parametrize("task", ["on_plate", "in_place"])
def test_distillation_configs_compose_with_the_tray_teacher(task, tiny_trueadapt):
    cfg = _cfg(f"iiwa7_trueadapt_{task}_distill", tiny_trueadapt.path, Path("unused"), 1)
    assert cfg["agent"]["algorithm"]["class_name"] == "Distillation"
    assert cfg["teacher"] == {"name": "trueadapt_tray"} and cfg["task"]["adapt"]["mode"] == task
    assert cfg["agent"]["obs_groups"]["student"] == ["policy"]  # the student sees the policy observation only


def test_tiny_distillation_lowers_the_loss_and_the_student_acts_on_the_policy_observation(tiny_trueadapt,
                                                                                           tmp_path):
    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.eval.trueadapt import evaluate
    from pathrl.runs import load_policy, load_run
    from pathrl.train.runner import train

    run_dir = tmp_path / "distill"
    summary = train(_cfg("iiwa7_trueadapt_on_plate_distill", tiny_trueadapt.path, run_dir, 6), run_dir)
    assert summary["iterations"] == 6
    loss = [m["values"]["Loss/behavior"] for t, _, m in read_messages(run_dir / "run.mcap") if t == "/train/scalars"]
    assert len(loss) == 6 and loss[-1] < 0.5 * loss[0], loss  # the untrained student is far from the controller

    cfg, ckpt, _ = load_run(run_dir)
    assert ckpt is not None and ckpt.name == "model_5.pt"
    env = build_trueadapt_env(cfg, "test", num_envs=4, autoreset=False)
    assert set(env.get_observations().keys()) == {"policy"}  # no teacher group, no controller: the policy's own view
    model = load_policy(cfg, env, ckpt)
    first = next(m for m in model.modules() if isinstance(m, torch.nn.Linear))
    assert first.in_features == env.num_obs
    with torch.no_grad():
        a = model(env.get_observations())
    assert a.shape == (4, env.num_actions) and bool(torch.isfinite(a).all()) and float(a.abs().max()) > 0.0
    m = evaluate(env, lambda e: model(e.get_observations()), torch.arange(4))
    assert bool(((m["fraction"] >= 0) & (m["fraction"] <= 1)).all()) and bool((m["acc"] > 0).all())


def test_recurrent_student_trains_loads_and_starts_each_batch_with_a_clear_memory(tiny_trueadapt, tmp_path):
    from rsl_rl.models import RNNModel

    from pathrl.envs.trueadapt import build_trueadapt_env
    from pathrl.eval.trueadapt import ObservingPolicy, run_trajectories
    from pathrl.runs import load_policy, load_run
    from pathrl.train.runner import train

    run_dir = tmp_path / "gru"
    train(_cfg("iiwa7_trueadapt_in_place_distill_gru", tiny_trueadapt.path, run_dir, 4), run_dir)
    loss = [m["values"]["Loss/behavior"] for t, _, m in read_messages(run_dir / "run.mcap") if t == "/train/scalars"]
    assert len(loss) == 4 and loss[-1] < loss[0], loss
    cfg, ckpt, _ = load_run(run_dir)
    env = build_trueadapt_env(cfg, "test", num_envs=2, autoreset=False)
    model = load_policy(cfg, env, ckpt)
    assert isinstance(model, RNNModel) and model.is_recurrent
    policy = ObservingPolicy(model)
    batch = torch.arange(2)
    first = run_trajectories(env, policy, batch)
    assert model.rnn.hidden_state is not None  # it carried a memory through the episodes
    fresh = build_trueadapt_env(cfg, "test", num_envs=2, autoreset=False)  # the same episodes, same random draws
    again = run_trajectories(fresh, policy, batch)  # the memory left by the first batch is cleared: same results
    for k in first:
        assert torch.equal(first[k], again[k]), k


def test_lr_decay_lowers_the_students_learning_rate_log_linearly(tiny_trueadapt, tmp_path):
    from pathrl.train.runner import log_linear, train

    run_dir = tmp_path / "decay"
    cfg = _cfg("iiwa7_trueadapt_in_place_distill_f10_decay", tiny_trueadapt.path, run_dir, 5)
    cfg["lr_decay"] = {"final": 1e-5, "start": 0.0}
    train(cfg, run_dir)
    rates = [m["values"]["Loss/learning_rate"] for t, _, m in read_messages(run_dir / "run.mcap")
             if t == "/train/scalars"]
    assert rates == pytest.approx([log_linear(it, 5, 1e-3, 1e-5, 0.0) for it in range(5)], rel=1e-9)
    assert rates[0] == pytest.approx(1e-3) and rates[-1] == pytest.approx(1e-5)
    saved = torch.load(run_dir / "model_4.pt", weights_only=True)
    assert saved["optimizer_state_dict"]["param_groups"][0]["lr"] == pytest.approx(1e-5)


#: The Table I state ablations trained by distillation: what each leaves out of (or adds to) the student's state.
ABLATIONS = {"full": (), "no_position": ("pos",), "no_velocity": ("vel",), "no_acceleration": ("acc",),
             "no_following": ("reference_1",), "f10": (), "open_loop": ()}


@pytest.mark.parametrize("variant", sorted(ABLATIONS))
def test_ablation_experiments_shape_the_students_state_and_keep_the_teacher(variant, tiny_trueadapt):
    from pathrl.envs.registry import EnvRequest, make_env
    from pathrl.train.runner import check_run_cfg

    cfg = _cfg(f"iiwa7_trueadapt_on_plate_distill_{variant}", tiny_trueadapt.path, Path("unused"), 1000)
    check_run_cfg(cfg)
    assert cfg["teacher"] == {"name": "trueadapt_tray"} and cfg["lr_decay"] == {"final": 1e-5, "start": 0.3}
    parts = [name for name, _, _ in make_env(cfg, EnvRequest(num_envs=2)).observation_layout()]
    full = ["pos", "vel", "acc", "prev_ball", "ball", "reference_1"]
    if variant == "f10":
        assert parts == full + [f"reference_{k}" for k in range(2, 11)]
    else:
        assert parts == [p for p in full if p not in ABLATIONS[variant]]
    assert cfg["task"]["observe"] is (variant != "open_loop")  # open loop: the teacher reads the frozen ball too
