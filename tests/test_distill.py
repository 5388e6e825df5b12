"""Distillation of a controller into the policy network (rsl-rl Distillation), warm start of PPO from the student,
critic warm-up."""

from __future__ import annotations

from pathlib import Path

import torch
from tensordict import TensorDict
from test_train import run, train_cmd

from pathrl.logging.mcap_io import read_messages
from pathrl.train.distill import TEACHER_GROUP, ControllerTeacher, TeacherLabels

BALL = ("task=ball_on_plate", "reward=ball_balancing", "knots=distance_5", "env.segments=full",
        "env.episode_budget_s=6.0", "env.scale_budget=false")
DISTILL = ("+experiment=iiwa7_ball_balancing_distill",)


class CountingController:
    def __init__(self, n: int, d: int):
        self.calls, self.n, self.d = 0, n, d

    def __call__(self, obs: TensorDict) -> torch.Tensor:
        self.calls += 1
        return torch.full((self.n, self.d), float(self.calls))


class StubEnv:
    num_envs, num_actions = 3, 2

    def get_observations(self) -> TensorDict:
        return TensorDict({"policy": torch.zeros(3, 5)}, batch_size=[3])

    def step(self, actions):
        return self.get_observations(), torch.zeros(3), torch.zeros(3), {}


def test_the_teacher_labels_each_state_once_and_the_teacher_model_returns_them():
    ctl = CountingController(3, 2)
    env = TeacherLabels(StubEnv(), ctl)
    first = env.get_observations()
    again = env.get_observations()  # the runner asks twice before the first step: the controller runs once
    assert ctl.calls == 1 and torch.equal(first[TEACHER_GROUP], again[TEACHER_GROUP])
    obs, *_ = env.step(torch.zeros(3, 2))
    assert ctl.calls == 2 and float(obs[TEACHER_GROUP][0, 0]) == 2.0
    assert env.num_actions == 2  # everything else is the wrapped env's
    teacher = ControllerTeacher(obs, {"teacher": [TEACHER_GROUP]}, "teacher", 2)
    assert torch.equal(teacher(obs), obs[TEACHER_GROUP]) and not list(teacher.parameters())


def scalars(run_dir: Path) -> list[dict]:
    return [m["values"] for t, _, m in read_messages(run_dir / "run.mcap") if t == "/train/scalars"]


def test_distillation_run_then_ppo_from_the_student_with_a_frozen_actor(tiny_dataset, tmp_path):
    """A tiny DAgger run with the ball controller as teacher lowers the behaviour loss; PPO then starts from the
    student: during the critic warm-up its actor is exactly the student, after it the actor learns."""
    student = tmp_path / "distill"
    r = run(train_cmd(tiny_dataset, student, 12, *DISTILL, "env.num_envs=64"))
    assert r.returncode == 0, r.stderr[-2000:]
    loss = [s["Loss/behavior"] for s in scalars(student)]
    assert len(loss) == 12 and loss[-1] < 0.5 * loss[0], loss
    r = run(train_cmd(tiny_dataset, student, 13, *DISTILL, "env.num_envs=64", "resume=true"))
    assert r.returncode == 0, r.stderr[-2000:]  # resume: student, optimizer and iteration (the teacher has no state)
    assert [s["Loss/behavior"] for s in scalars(student)][:12] == loss and len(scalars(student)) == 13
    ck = torch.load(student / "model_12.pt", weights_only=True)
    assert "student_state_dict" in ck and ck["infos"]["wall_time_s"] > 0

    ppo = tmp_path / "ppo"
    frozen = ("+experiment=iiwa7_ball_balancing_finetune", f"init_from={student}", "critic_warmup.iterations=2",
              "critic_warmup.freeze_normalizer=true")
    r = run(train_cmd(tiny_dataset, ppo, 3, *frozen))
    assert r.returncode == 0, r.stderr[-2000:]
    s = ck["student_state_dict"]
    norm = [k for k in s if k.startswith("obs_normalizer.")]
    assert norm
    for it, same in ((0, True), (1, True), (2, False)):  # checkpoints are taken after each iteration's update
        actor = torch.load(ppo / f"model_{it}.pt", weights_only=True)["actor_state_dict"]
        assert actor.keys() == s.keys()
        assert all(torch.equal(actor[k], s[k]) for k in s) is same, it
        assert all(torch.equal(actor[k], s[k]) for k in norm), it  # freeze_normalizer: the inputs never move
    critic0 = torch.load(ppo / "model_0.pt", weights_only=True)["critic_state_dict"]
    critic1 = torch.load(ppo / "model_1.pt", weights_only=True)["critic_state_dict"]
    assert not torch.equal(critic0["mlp.0.weight"], critic1["mlp.0.weight"])  # the critic learns meanwhile


def test_distillation_needs_a_teacher_and_no_warm_start(tiny_dataset, tmp_path):
    r = run(train_cmd(tiny_dataset, tmp_path / "a", 1, *BALL, "agent=distillation", "std_anneal=null"))
    assert r.returncode == 2 and "teacher" in r.stderr.strip().splitlines()[-1]
    r = run(train_cmd(tiny_dataset, tmp_path / "b", 1, *DISTILL, f"init_from={tmp_path}"))
    assert r.returncode == 2 and "init_from" in r.stderr.strip().splitlines()[-1]
    r = run(train_cmd(tiny_dataset, tmp_path / "c", 1, *DISTILL, "teacher.name=lqr"))
    assert r.returncode == 2 and "unknown name" in r.stderr.strip().splitlines()[-1]
