"""Training, resume, kill-safety of run.mcap and evaluation on a tiny synthetic dataset (CLI smoke runs)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from pathrl.logging.mcap_io import read_messages
from pathrl.repro.figures import learning_curves
from pathrl.train.ship import read_curve, ship

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def train_cmd(dataset, run_dir, iterations, *extra):
    return [str(BIN / "pathrl-train"), f"dataset.path={dataset}", f"run_dir={run_dir}", f"iterations={iterations}",
            "env.num_envs=32", "agent.num_steps_per_env=8", "agent.save_interval=1", "compile_limits=false", *extra]


def run(cmd, **kw):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env, timeout=300, **kw)


def scalars(run_dir):
    return [m for t, _, m in read_messages(run_dir / "run.mcap") if t == "/train/scalars"]


def _files(run_dir):
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in run_dir.iterdir() if p.is_file()}


def test_train_resume_and_eval(tiny_dataset, tmp_path):
    run_dir = tmp_path / "rün dir"  # non-ASCII and a space: quoted for Hydra's grammar by the CLI (issue 50)
    r = run(train_cmd(tiny_dataset, run_dir, 2))
    assert r.returncode == 0, r.stderr[-2000:]
    assert (run_dir / "config.yaml").is_file() and (run_dir / "model_1.pt").is_file()
    assert [m["iteration"] for m in scalars(run_dir)] == [0, 1]
    topics = {t for t, _, _ in read_messages(run_dir / "run.mcap")}
    assert "/run/config" in topics
    # a second run into the same dir without resume is refused, nothing is lost
    r = run(train_cmd(tiny_dataset, run_dir, 2))
    assert r.returncode != 0 and "resume=true" in r.stderr
    # resume continues at iteration 2
    r = run(train_cmd(tiny_dataset, run_dir, 4, "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert [m["iteration"] for m in scalars(run_dir)] == [0, 1, 2, 3]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["iterations"] == 4 and summary["env_steps"] == 4 * 32 * 8
    # a resume with nothing left to do changes nothing (it used to rewrite summary.json with mean_reward null)
    before = _files(run_dir)
    r = run(train_cmd(tiny_dataset, run_dir, 4, "resume=true"))
    assert r.returncode == 0 and "nothing to do, nothing changed" in r.stderr, r.stderr[-2000:]
    assert _files(run_dir) == before and summary["mean_reward"] is not None
    # resume with a different config is refused
    r = run(train_cmd(tiny_dataset, run_dir, 5, "resume=true", "reward=balanced"))
    assert r.returncode != 0 and "different config" in r.stderr

    out = tmp_path / "eval"
    r = run([str(BIN / "pathrl-eval"), f"run_dir={run_dir}", "compile_limits=false",
             "episodes=4", f"out={out}", "segments=full"])
    assert r.returncode == 0, r.stderr[-2000:]
    m = json.loads((out / "metrics.json").read_text())
    assert m["episodes"] == 4 and len(m["per_episode"]) == 4
    for key in ("duration_s", "joint_dev_mean_rad", "cart_pos_dev_mean_cm", "cart_rot_dev_max_deg",
                "terminated_early_pct", "limit_violations"):
        assert key in m
    assert m["limit_violations"] == 0
    topics = {t for t, _, _ in read_messages(out / "episodes.mcap")}
    assert {"/eval/robot", "/eval/reference", "/eval/joint_state", "/eval/tcp", "/eval/episode_metrics"} <= topics

    # shipping keeps the learning curve: one row per iteration from run.mcap, drawn by the reproduce figure
    dest = ship(run_dir, tmp_path / "shipped")
    c = read_curve(dest / "curve.csv")
    assert c["iteration"].tolist() == [0, 1, 2, 3] and c["env_steps"].tolist() == [256, 512, 768, 1024]
    assert np.all(np.diff(c["wall_time_s"]) > 0) and "Episode_Termination/time_out" in c and "Policy/mean_std" in c
    assert learning_curves({"a": c, "b": c}, "tiny", tmp_path / "lc.png") and (tmp_path / "lc.png").is_file()
    assert not learning_curves({}, "none", tmp_path / "none.png") and not (tmp_path / "none.png").exists()

    # time-to-quality curve over the checkpoints of iterations 0, 2 (every 2) and the last one (3)
    curve = tmp_path / "curve"
    r = run([sys.executable, "tools/lab/time_to_quality.py", "--run", str(run_dir), "--row", "iiwa7/random",
             "--dataset", str(tiny_dataset), "--every", "2", "--episodes", "3", "--out", str(curve)])
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads((curve / "curve.json").read_text())["runs"][0]
    assert [p["iteration"] for p in rec["points"]] == [1, 3, 4]
    assert [p["env_steps"] for p in rec["points"]] == [256, 768, 1024]
    walls = [p["wall_time_s"] for p in rec["points"]]
    assert all(w > 0 for w in walls) and walls == sorted(walls)
    assert rec["target"] == {"max_duration_s": 4.28, "max_dev_cm": 3.3} and (curve / "curve.png").is_file()
    # whole paths (the ball-balancing row's protocol): one episode per test path
    r = run([sys.executable, "tools/lab/time_to_quality.py", "--run", str(run_dir), "--dataset", str(tiny_dataset),
             "--every", "4", "--segments", "full", "--out", str(tmp_path / "curve_full")])
    assert r.returncode == 0, r.stderr[-2000:]
    rec = json.loads((tmp_path / "curve_full" / "curve.json").read_text())["runs"][0]
    assert rec["segments"] == "full" and [p["iteration"] for p in rec["points"]] == [1, 4]
    full = [json.loads(f.read_text()) for f in (tmp_path / "curve_full").glob("*/model_*/metrics.json")]
    assert len(full) == 2 and all(m["segments"] == "full" and m["episodes"] == len(m["per_episode"]) for m in full)
    rows = (tmp_path / "curve_full" / f"{str(run_dir).replace('/', '_')}.csv").read_text().splitlines()
    assert rows[0].startswith("iteration,env_steps,wall_time_s,duration_s,cart_pos_dev_mean_cm,limit_violations,")
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "4"] and all(r.endswith(",") for r in rows[1:])  # no task
    r = run([sys.executable, "tools/lab/time_to_quality.py", "--run", str(run_dir), "--row", "iiwa7/nowhere",
             "--out", str(curve)])
    assert r.returncode == 2 and "not a Table I row" in r.stderr


def test_run_mcap_survives_kill(tiny_dataset, tmp_path):
    run_dir = tmp_path / "killed"
    env = dict(os.environ, OMP_NUM_THREADS="1")
    p = subprocess.Popen(train_cmd(tiny_dataset, run_dir, 1000), cwd=ROOT, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        while time.time() < deadline:
            if (run_dir / "run.mcap").exists() and len(scalars(run_dir)) >= 3:
                break
            time.sleep(0.5)
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait()
    got = scalars(run_dir)
    assert len(got) >= 3
    assert [m["iteration"] for m in got] == list(range(len(got)))
    killed_wall = json.loads((run_dir / "summary.json").read_text())["wall_time_s"]  # recorded at checkpoints
    assert killed_wall > 0.0
    # and the killed run resumes from its last checkpoint; its wall time keeps the killed process's share
    r = run(train_cmd(tiny_dataset, run_dir, len(got) + 2, "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads((run_dir / "summary.json").read_text())["wall_time_s"] > killed_wall
    # every iteration logged exactly once: what the killed run logged after its last checkpoint was dropped
    assert [m["iteration"] for m in scalars(run_dir)] == list(range(len(got) + 2))


def test_ball_task_warm_start_train_and_pybullet_eval(tiny_dataset, tmp_path):
    """Tracking run -> warm-started ball run (analytic ball model) -> evaluation in PyBullet, all from the CLI."""
    src, ball = tmp_path / "tracking", tmp_path / "ball"
    r = run(train_cmd(tiny_dataset, src, 1))
    assert r.returncode == 0, r.stderr[-2000:]
    r = run(train_cmd(tiny_dataset, ball, 1, "task=ball_on_plate", "reward=ball_balancing", f"init_from={src}"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "ball_centre" in json.dumps(scalars(ball)[0])
    out = tmp_path / "eval"
    r = run([str(BIN / "pathrl-eval"), f"run_dir={ball}", "compile_limits=false",
             "episodes=2", "segments=full", f"out={out}"])
    assert r.returncode == 0, r.stderr[-2000:]
    m = json.loads((out / "metrics.json").read_text())
    task_msgs = [msg for t, _, msg in read_messages(out / "episodes.mcap") if t == "/eval/task"]
    assert task_msgs and {"episode", "t", "ball_dist", "ball_on_plate"} <= set(task_msgs[0])
    assert m["task"] == {"name": "ball_on_plate", "backend": "PyBulletBall", "simulator": "pybullet", "observed": True,
                         "open_loop": False}
    assert 0.0 <= m["task_failed_pct"] <= 100.0 and len(m["per_episode"]) == 2
    # the tracking run evaluated with the ball riding along unobserved
    r = run([str(BIN / "pathrl-eval"), f"run_dir={src}", "compile_limits=false",
             "episodes=2", "segments=full", f"out={out}",
             "record=false", "task=ball_on_plate", "backend=analytic"])
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads((out / "metrics.json").read_text())["task"]["observed"] is False
    # a warm start from nowhere is one clear line
    r = run(train_cmd(tiny_dataset, tmp_path / "x", 1, f"init_from={tmp_path / 'missing'}"))
    assert r.returncode != 0 and "init_from" in r.stderr.strip().splitlines()[-1]


def test_ball_task_from_scratch_with_an_asymmetric_critic_trains_and_evaluates_in_pybullet(tiny_dataset, tmp_path):
    """The Table VII from-scratch recipe (task.critic_obs, the critic reads policy + critic groups, a noise floor):
    the critic's first layer takes the privileged inputs, the actor does not; PyBullet evaluation loads the actor."""
    run_dir = tmp_path / "scratch"
    r = run(train_cmd(tiny_dataset, run_dir, 1, "+experiment=iiwa7_ball_balancing_reward_scratch"))
    assert r.returncode == 0, r.stderr[-2000:]
    state = torch.load(run_dir / "model_0.pt", weights_only=True)
    actor_in = next(v for k, v in state["actor_state_dict"].items() if k.endswith("weight")).shape[1]
    critic_in = next(v for k, v in state["critic_state_dict"].items() if k.endswith("weight")).shape[1]
    assert critic_in == actor_in + 6  # time left, arc length left, ball velocity (2), radius, rolling friction
    r = run([str(BIN / "pathrl-eval"), f"run_dir={run_dir}", "compile_limits=false", "episodes=2", "segments=full",
             f"out={tmp_path / 'eval'}", "record=false"])
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads((tmp_path / "eval" / "metrics.json").read_text())["task"]["backend"] == "PyBulletBall"


def test_resume_accepts_keys_added_later_only_at_their_old_behaviour():
    from pathrl.train.runner import config_change

    saved = {"env": {"num_envs": 8}, "iterations": 5}
    now = {"env": {"num_envs": 8, "free_joint_actions": "linear", "posture_omega": 3.0}, "iterations": 9}
    assert config_change(saved, now) == ""
    now["env"]["free_joint_actions"] = "posture"
    assert "free_joint_actions" in config_change(saved, now)
