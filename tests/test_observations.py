"""Observation terms (pathrl.envs.observations): the layout of every registered task's env covers its observation
exactly, the terms keep their fixed order (state, feedback, tcp: shipped policies depend on it), and the state
term by hand."""

from __future__ import annotations

import pytest
import torch
from test_env import make_env as make_tracking_env
from test_env import smooth_paths

from pathrl.cli.common import compose, to_container
from pathrl.envs.observations import (
    OBS_ORDER,
    OBS_TERMS,
    observe_state,
    state_fields,
    state_size,
    tcp_observation,
    tracking_state,
)
from pathrl.envs.registry import EVAL_ENV, TASKS, EnvRequest, make_env
from pathrl.paths.pathset import build_pathset
from pathrl.robot.model import load_robot
from pathrl.schema import TrainAppCfg

#: A small env of each registered task and config variant: (task, config overrides, dataset fixture or None:
#: synthetic paths of the config's robot).
VARIANTS = {
    "tracking": ("tracking", [], "tiny_dataset"),
    "tracking_end_absolute": ("tracking", ["env.end_obs=true", "env.knot_obs=absolute", "knots.n_state=4"],
                              "tiny_dataset"),
    "ball_on_plate": ("ball_on_plate", ["task=ball_on_plate"], "tiny_dataset"),
    "ball_on_plate_imu_tcp": ("ball_on_plate", ["task=ball_on_plate", "task.imu=true", "env.tcp_obs=true"],
                              "tiny_dataset"),
    "ball_on_plate_unobserved_tcp": ("ball_on_plate", ["task=ball_on_plate", "task.observe=false", "env.tcp_obs=true"],
                                     "tiny_dataset"),
    "standing": ("standing", ["+experiment=armar4_target_point_balancing", "task.workers=1"], None),
    "trueadapt_on_plate": ("trueadapt_on_plate", ["+experiment=iiwa7_trueadapt_on_plate"], "tiny_trueadapt"),
    "trueadapt_in_place": ("trueadapt_in_place", ["+experiment=iiwa7_trueadapt_in_place"], "tiny_trueadapt"),
}


def _build(variant: str, request):
    task, overrides, fixture = VARIANTS[variant]
    cfg = to_container(compose("train", overrides, TrainAppCfg))
    if fixture is None:  # PyBullet feedback: one env on synthetic paths of the robot
        robot = load_robot(cfg["robot"])
        knots = smooth_paths(robot)
        paths = build_pathset(knots, [f"p{i}" for i in range(len(knots))])
        return make_env(cfg, EnvRequest("test", num_envs=1, seed=0, paths=paths, robot=robot), **EVAL_ENV)
    data = request.getfixturevalue(fixture)
    return make_env(cfg, EnvRequest("test", num_envs=2, seed=0, dataset_path=str(getattr(data, "path", data))))


def _close(env) -> None:
    fb = getattr(env, "feedback", None) or getattr(env, "ball", None)
    if fb is not None:
        fb.close()


def _covers(layout: list[tuple[str, int, int]], num_obs: int) -> None:
    """The slices are non-empty, contiguous from column 0 and end at num_obs; names are unique."""
    assert layout[0][1] == 0 and layout[-1][2] == num_obs
    assert all(start < stop for _, start, stop in layout)
    assert all(a[2] == b[1] for a, b in zip(layout, layout[1:], strict=False))
    assert len({name for name, _, _ in layout}) == len(layout)


def test_every_task_has_a_variant():
    assert {task for task, _, _ in VARIANTS.values()} == set(TASKS)


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_layout_covers_the_observation(variant, request):
    env = _build(variant, request)
    try:
        obs = env.step(torch.zeros(env.num_envs, env.num_actions))[0]["policy"]
        layout = env.observation_layout()
        _covers(layout, env.num_obs)
        assert obs.shape[1] == env.num_obs and env.describe()["obs_layout"] == [list(s) for s in layout]
        if TASKS[VARIANTS[variant][0]].adapt:
            return
        names = [name for name, _, _ in layout]
        assert names == [t for t in OBS_ORDER if t in names] and names[0] == "state"  # the fixed order
        assert ("feedback" in names) == (env.feedback is not None and env.cfg.feedback_obs)
        assert ("tcp" in names) == env.cfg.tcp_obs and ("error" in names) == env.cfg.error_obs
        detailed = env.observation_layout(fields=True)
        _covers(detailed, env.num_obs)
        assert detailed[-1][2] - detailed[0][1] == env.num_obs
        assert [s for s in detailed if not s[0].startswith("state/")] == layout[1:]
    finally:
        _close(env)


def test_term_order_is_fixed():
    assert OBS_ORDER == ("state", "feedback", "tcp", "error") == tuple(OBS_TERMS)


def test_each_term_fills_its_slice_in_the_shipped_order(request):
    """The observation is the shipped concatenation (state, feedback, tcp; clipped, float32), and each term's
    values (clipped) are the columns of its slice."""
    env = _build("ball_on_plate_imu_tcp", request)
    try:
        gen = torch.Generator().manual_seed(0)
        for _ in range(4):
            obs = env.step(torch.rand(env.num_envs, env.num_actions, generator=gen) * 2 - 1)[0]["policy"]
        state, _, _ = tracking_state(env)
        ref = env.pos.clone()
        ref[:, env.path_index] = env.paths.position_at(env.seg_path, env.s)
        tcp = env.fk.tcp_positions(torch.cat([ref, env.pos]))
        tcp_part = tcp_observation(tcp[:env.num_envs], tcp[env.num_envs:], env.tcp_box, env.cfg.tcp_obs_error)
        shipped = torch.cat([state, env.feedback.observe().to(state.dtype), tcp_part], dim=1)
        assert torch.equal(obs, shipped.clamp(-1.0, 1.0).to(torch.float32))
        for name, start, stop in env.observation_layout():
            values = OBS_TERMS[name].observe(env)
            assert values.shape[1] == OBS_TERMS[name].size(env) == stop - start
            assert torch.equal(obs[:, start:stop], values.clamp(-1.0, 1.0).to(torch.float32)), name
    finally:
        _close(env)


def test_state_term_by_hand():
    """Two path joints, a window of 2 knots on the path (0, 0) -> (1, 0) -> (1, 1), knot gap 1, robot at s = 0.5."""
    f64 = dict(dtype=torch.float64)
    knots = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]], **f64)  # (P=1, K=3, M=2)
    knot_s = torch.tensor([[0.0, 1.0, 2.0]], **f64)
    pos, vel, acc = (torch.tensor([v], **f64) for v in ([0.5, 0.0], [0.2, 0.0], [0.0, -0.5]))
    pos_lim = torch.tensor([[-1.0, 1.0], [-2.0, 2.0]], **f64)
    one = torch.zeros(1, dtype=torch.long)
    state, l_obs, close = observe_state(
        pos, vel, acc, pos_lim, torch.tensor([1.0, 1.0], **f64), torch.tensor([2.0, 2.0], **f64), torch.tensor([0, 1]),
        knots, knot_s, one * 0, one * 0, torch.tensor([0.5], **f64), one + 2, torch.tensor([[1.0, 1.0]], **f64),
        torch.tensor([2.0], **f64), 2, 1.0, 1.0, True, True)
    expected = [0.5, 0.0,  # pos: 2 (0.5 + 1) / 2 - 1, 2 (0 + 2) / 4 - 1
                0.2, 0.0,  # vel / v_max
                0.0, -0.25,  # acc / a_max
                -0.5, 0.0, 0.5, 0.0,  # knots 0 and 1 minus the robot, / horizon 1
                0.0,  # inside: 2 (0.5 - 0) / 1 - 1
                1.0,  # window: 2 (1 - 0) / 1 - 1
                1.0,  # ahead: knot 1
                0.5, 1.0,  # to_end: (1, 1) - (0.5, 0)
                1.0]  # left: 2 clamp(1.5, 0, 1) - 1
    assert state_size(2, 2, 2, True) == len(expected) == sum(k for _, k in state_fields(2, 2, 2, True))
    torch.testing.assert_close(state, torch.tensor([expected], **f64), rtol=0.0, atol=1e-15)
    assert float(l_obs) == 1.0 and not bool(close)  # the window ends at knot 1, short of the end knot


def test_tracking_env_layout_without_a_registry_config():
    """An env built directly (tests, scripts): state and tcp slices by the terms' size functions."""
    env, _ = make_tracking_env("armar6", num_envs=2, tcp_obs=True, end_obs=True)
    robot = env.robot
    n_state = state_size(robot.dof, robot.path_dof, env.cfg.n_state, True)
    assert env.observation_layout() == [("state", 0, n_state), ("tcp", n_state, n_state + 6 * len(robot.tcps))]
    assert env.num_obs == n_state + 6 * len(robot.tcps)
