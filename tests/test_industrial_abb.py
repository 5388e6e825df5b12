"""The controller model calibrated to the recorded ABB controller (issue 47): planner look-ahead and zone
degradation, drive dynamics (gravity hold, gear elasticity), the curve-1 calibration and a tiny ILC run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pathrl import native
from pathrl.industrial import drives, dynamics
from pathrl.industrial.controller import ControllerParams, execute
from pathrl.industrial.ilc import ILCParams, run_ilc
from pathrl.industrial.planner import PlannerParams, plan, plan_zones
from pathrl.industrial.program import Program
from pathrl.industrial.trajectories import Target

DOWN = np.diag([1.0, -1.0, -1.0])  # tool z pointing down


def _program(points, zone=10.0) -> Program:
    pts = np.asarray(points, dtype=float)
    return Program(pts, np.repeat(DOWN[None], len(pts), 0), "L", zone)


def test_short_segment_at_high_speed_degrades_the_zone_to_a_fine_point():
    # waypoints 1 and 2 are 2 mm apart, closer than the z10 zone: at 1000 mm/s the segment lasts 2 ms, less than
    # the 8 ms preparation time, so the zone at waypoint 2 becomes a fine point (a corner event)
    pts = [[1500, -200, 800], [1500, 0, 800], [1500, 2, 800], [1500, 2, 1000]]
    radii, fine, events = plan_zones(np.array(pts, float), 10.0, 1000.0, PlannerParams())
    assert [e.waypoint for e in events] == [2] and math.isclose(events[0].segment_s, 0.002)
    assert fine.tolist() == [True, False, True, True] and radii[2] == 0.0
    assert radii[1] == pytest.approx(1.0)  # shrunk to half the 2 mm segment
    # at 50 mm/s the segment lasts 40 ms: the zone is kept, shrunk to half the short segment
    radii, fine, events = plan_zones(np.array(pts, float), 10.0, 50.0, PlannerParams())
    assert events == [] and radii[2] == pytest.approx(1.0) and not fine[1:3].any()
    # the planned speed comes (almost: the 32 ms moving average of s(t) rounds the stop) to rest there
    pl = plan(_program(pts), 1000.0)
    at = np.argmin(np.abs(pl.s - 202.0))
    assert pl.sdot[at - 2: at + 3].min() < 0.05 * 1000.0
    ex = execute(_program(pts), 1000.0, ControllerParams(model="abb"))
    assert [e.waypoint for e in ex.events] == [2]


def test_finite_lookahead_caps_the_speed_on_short_segments():
    # 81 collinear waypoints 10 mm apart: holding 5 instructions (50 mm) the planner must be able to stop within
    # them, so v^2 <= 2 a_tcp 50 mm: 632 mm/s at 4000 mm/s^2, whatever the command (1000 mm/s); the moving
    # average of s(t) overshoots such a plateau by ~2 %
    pts = [[1500.0, -300.0 + 10.0 * i, 800.0] for i in range(81)]
    cap = math.sqrt(2 * 4000.0 * 50.0)
    short = plan(_program(pts), 1000.0, PlannerParams(lookahead=5))
    assert cap * 0.97 < short.sdot.max() <= cap * 1.03
    long = plan(_program(pts), 1000.0, PlannerParams(lookahead=80))
    assert long.sdot.max() == pytest.approx(1000.0, rel=0.01)


def _nominal_gears(params: drives.DriveParams):
    true = dynamics.cached(dynamics.nominal())
    m = true.mass_matrix(drives.NOMINAL_Q[None])[0]
    return true, m, *drives.gear_matrices(m, params)


def test_gravity_holds_the_arm_at_rest_under_the_servo():
    params = drives.DriveParams(start_jitter_s=0.0, friction_var=0.0)
    true, _, k, d = _nominal_gears(params)
    model = dynamics.cached(dynamics.perturbed(dynamics.nominal(), params.model_error, params.model_seed))
    q_r = np.repeat(drives.NOMINAL_Q[None], 500, 0)  # 2 s at rest at 250 Hz
    q = drives.simulate(q_r, 250.0, true, model, k, d, params, np.random.default_rng(0))
    assert np.abs(q - q[0]).max() < 1e-6  # it does not sag or drift
    # what is left is the feed-forward model's gravity error over the gear: (g - g^) / K, by hand
    g_err = (true.bias(q_r[:1], np.zeros((1, 6))) - model.bias(q_r[:1], np.zeros((1, 6))))[0] / k
    np.testing.assert_allclose(q[-1] - q_r[-1], -g_err, atol=2e-6)


def test_gear_step_overshoots_by_the_configured_elasticity():
    params = drives.DriveParams(gear_zeta=0.1)
    _, m, k, d = _nominal_gears(params)
    for axis in (0, 5):
        q = drives.gear_step(m[axis, axis], k[axis], d[axis], 1e-3, 0.3)
        zeta, w = params.gear_zeta, 2 * np.pi * params.gear_hz[axis]
        overshoot = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))
        assert (q.max() - 1e-3) / 1e-3 == pytest.approx(overshoot, rel=0.02)
        assert np.argmax(q) * 1e-4 == pytest.approx(math.pi / (w * math.sqrt(1 - zeta**2)), rel=0.02)


def _recorded_drive_loop(monkeypatch) -> tuple:
    """The drive loop's arguments in an ABB-model execution of a short MoveL program (recorded on the way)."""
    calls = []
    monkeypatch.setattr(drives, "drive_loop", lambda *args: calls.append(args) or drives.drive_loop_python(*args))
    execute(_program([[1500, -200, 800], [1500, 0, 800], [1500, 100, 1000]]), 500.0, ControllerParams(model="abb"))
    assert len(calls) == 1
    return calls[0]


def test_native_drive_loop_matches_the_python_loop(monkeypatch):
    if not native.available():
        pytest.skip("native code unavailable")
    args = _recorded_drive_loop(monkeypatch)
    monkeypatch.undo()
    state = [x.copy() for x in args[2]]
    q_py, q_c = drives.drive_loop_python(*args), native.drive_loop(*args)
    assert q_c.shape == q_py.shape == (len(args[0][0]), 6) and len(q_py) > 500
    assert np.ptp(q_py, axis=0).max() > 0.1  # the arm moves
    assert np.abs(q_c - q_py).max() <= 1e-9
    assert all(np.array_equal(a, b) for a, b in zip(args[2], state, strict=True))  # initial state kept
    np.testing.assert_array_equal(drives.drive_loop(*args), q_c)  # used where available
    monkeypatch.setattr(native, "available", lambda: False)
    np.testing.assert_array_equal(drives.drive_loop(*args), q_py)  # the Python loop otherwise


@pytest.mark.parametrize("impl", ["python", "native"])
def test_drive_loop_two_steps_by_hand(impl):
    """dt 0.5, kp 2, kv 1, ki 0, no friction, b 1, K 4, D 2, M^-1 = I, setpoint 1 on axes 0 and 1 (torque limit
    0.5 on axis 1). Axis 0, step 1: ev 2, tau_m 2, thd 1, th 0.5; step 2: ev 0, tau_s 4 * 0.5 + 2 * 1 = 4, thd -1,
    qd 2, q 1. Axis 1: tau_m 0.5, thd 0.25, th 0.125; ev 1.5 -> 0.5, tau_s 1, thd 0, qd 0.5, q 0.25."""
    if impl == "native" and not native.available():
        pytest.skip("native code unavailable")
    loop = drives.drive_loop_python if impl == "python" else native.drive_loop
    th_r = np.zeros((2, 6))
    th_r[:, :2] = 1.0
    zeros = np.zeros((2, 6))
    series = (th_r, zeros, zeros, zeros, np.repeat(np.eye(6)[None], 2, 0))
    ones = np.ones(6)
    axes = (2 * ones, ones, 0 * ones, np.r_[10.0, 0.5, 10.0, 10.0, 10.0, 10.0], 4 * ones, 2 * ones, ones,
            0 * ones, 0 * ones)
    q = loop(series, axes, tuple(np.zeros(6) for _ in range(5)), 1.0, 0.0, 0.5)
    np.testing.assert_array_equal(q[:, :2], [[0.0, 0.0], [1.0, 0.25]])
    assert not q[:, 2:].any()


def test_curve1_calibration_against_the_recording():
    from pathrl.industrial import reference as ref

    prog = ref.curve1_program()
    slow = ref.measure(execute(prog, 123.05, ControllerParams(model="abb")), 123.05)
    fast = ref.measure(execute(prog, 300.0, ControllerParams(model="abb")), 300.0)
    rec_slow, rec_fast = ref.RECORDED[123.05], ref.RECORDED[300.0]
    # targets the model meets (docs/industrial.md, calibration table; seed 0)
    for got, rec in ((slow.max_err, rec_slow[0]), (slow.mean_err, rec_slow[1]), (fast.max_err, rec_fast[0]),
                     (fast.mean_err, rec_fast[1])):
        assert abs(got / rec - 1) <= 0.2
    assert slow.speed_std_pct <= 1.0 and abs(slow.mean_speed / 123.05 - 1) < 0.01
    assert slow.max_at >= 0.8 and fast.max_at >= 0.8  # the max error in the last 20 % of the curve
    assert slow.ramp95_s <= 0.15  # rest to 95 % of the command (recorded 0.10-0.12 s)
    assert slow.ramp95_s == pytest.approx(0.108, abs=0.005) and fast.max_at == pytest.approx(0.997, abs=0.005)


def test_tiny_ilc_run_lowers_the_error():
    x = np.linspace(0.0, 300.0, 601)
    p = np.stack([1500.0 + 40.0 * np.sin(x / 300.0 * 2 * np.pi), x - 150.0, np.full_like(x, 900.0)], 1)
    target = Target("arc", p, np.repeat(DOWN[None], len(p), 0), speed=300.0)
    idx = np.round(np.linspace(0, len(p) - 1, 21)).astype(int)
    prog = _program(p[idx], zone=10.0)
    ctrl = ControllerParams(model="abb")
    for kind in ("p", "filtered"):
        res = run_ilc(target, prog, 300.0, ILCParams(kind=kind, gain=1.0, k_max=2), ctrl)
        assert res.executions >= 2 and res.errors.max_pos_mm < res.history[0]


def test_path_noise_has_the_set_std_and_correlates_neighbours():
    from pathrl.industrial.rl_train import path_noise

    rng = np.random.default_rng(0)
    white = np.stack([path_noise(rng, 100, 0.2, 0.0) for _ in range(200)])  # (200, 100, 3)
    smooth = np.stack([path_noise(rng, 100, 0.2, 3.0) for _ in range(200)])
    for x in (white, smooth):
        assert x.std() == pytest.approx(0.2, rel=0.05)
    corr = [np.corrcoef(x[:, 50, 0], x[:, 51, 0])[0, 1] for x in (white, smooth)]
    # neighbours of a Gaussian-smoothed white sequence (width 3): exp(-1 / (4 * 3^2)) = 0.97; white: 0
    assert abs(corr[0]) < 0.2 and corr[1] == pytest.approx(math.exp(-1 / 36), abs=0.05)


def test_actor_stats_in_action_units():
    from pathrl.industrial.rl_train import actor_stats

    mean = np.array([[0.5, -1.0, 0.0], [0.5, 0.0, 0.99]])
    out = actor_stats(mean, 2.0)
    assert out == {"a1": 1.0, "a2": -1.0, "a3": 0.99, "at_clip": pytest.approx(2 / 6)}


def test_critic_action_gain_scales_only_the_action_input():
    import torch

    from pathrl.industrial.rl import RLParams, _Critic

    torch.manual_seed(0)
    plain, scaled = _Critic([8]), _Critic([8], action_gain=10.0)
    scaled.load_state_dict(plain.state_dict())
    obs, act = torch.randn(4, 313), torch.rand(4, 3) * 0.1
    assert torch.allclose(scaled(obs, act), plain(obs, 10.0 * act))
    with pytest.raises(ValueError, match="critic_action_gain"):
        RLParams(critic_action_gain=0.0)
    with pytest.raises(ValueError, match="expl_smooth"):
        RLParams(expl_smooth=-1.0)


def test_ilc_columns_follow_the_controller_model():
    from pathrl.industrial.ilc import ILCColumns

    assert ILCColumns().variants("lag") == {}
    both = ILCColumns().variants("abb")
    assert list(both) == ["ILC P", "ILC filtered"] and both["ILC P"].kind == "p" and both["ILC P"].gain == 1.0
    assert list(ILCColumns(columns="always").variants("lag")) == ["ILC P", "ILC filtered"]
    assert ILCColumns(columns="never").variants("abb") == {}
    with pytest.raises(ValueError, match="ilc.columns"):
        ILCColumns(columns="sometimes")


def test_table2_markdown_with_ilc_columns_and_per_row_ratios():
    from pathrl.industrial.tables import Table2Row, per_row_ratio, table2_markdown

    # MPGD 4 and 6 iterations, ILC 2 and 2 (a third row: ILC misses): ratios 2 and 3 -> mean 2.5, totals 10/4
    assert per_row_ratio([4, 6, 9], [2, 2, None]) == (2, 2.5, 2.5)
    assert per_row_ratio([None], [1]) is None and per_row_ratio([0], [2])[1] == 0.5  # 0 counts as 1
    rows = [Table2Row("a", 1, 250.0, 2.0, 0.4, 4, 1.0, 5, ilc=(("ILC P", 0.45, 2),)),
            Table2Row("b", 1, 250.0, 2.0, 0.4, 6, 1.0, 7, ilc=(("ILC P", 0.30, 2),)),
            Table2Row("c", 1, 250.0, 2.0, 0.6, None, 1.0, 51, ilc=(("ILC P", 0.70, None),))]
    text = table2_markdown(rows, "cmd")
    assert "| ILC P err. (mm) | ILC P itr. |" in text and "| 0.70 | N/A |" in text
    assert "ILC P reached 0.5 mm on 2/3, mean 2.0 iterations; MPGD / ILC P iterations on the 2 rows both " \
           "reach: 2.50x (mean of per-row ratios; totals 2.50x)." in text
    # without ILC the table is what it was (no ILC column)
    assert "ILC" not in table2_markdown([Table2Row("a", 1, 250.0, 2.0, 0.4, 4, 1.0, 5)], "cmd")


def test_joint_smoothing_window_shrinks_at_the_motion_ends():
    from pathrl.industrial.planner import moving_average, moving_average_in_motion

    # rest at 0 for samples 0-2, then a ramp 1, 2, ..., 6 (constant speed): a centred window never averages the
    # rest in, so the ramp is kept exactly (a line is its own average); padding with rest ("hold") lags it
    x = np.r_[np.zeros(3), np.arange(1.0, 7.0)][:, None]
    out = moving_average_in_motion(x, 5, first=2, last=len(x) - 1)
    assert np.allclose(out, x)
    assert moving_average(x, 5)[3, 0] == pytest.approx((0 + 0 + 1 + 2 + 3) / 5)
    # a kink is averaged over the full window inside the motion: samples 1..5 around 3 of |i - 3|
    y = np.abs(np.arange(7.0) - 3.0)[:, None]
    assert moving_average_in_motion(y, 5, 0, 6)[3, 0] == pytest.approx((2 + 1 + 0 + 1 + 2) / 5)


def test_start_mode_shrinks_the_window_at_the_start_only():
    from pathrl.industrial.planner import moving_average_in_motion

    # rest at 0 (samples 0-2), a ramp 1..6, rest at 6 (samples 8-11): at the start the window shrinks (the ramp is
    # kept: 1 at sample 3), at the stop it runs over the held end point: sample 7 = (3 + 4 + 5 + 6 + 6) / 5 = 4.8
    x = np.r_[np.zeros(3), np.arange(1.0, 7.0), np.full(3, 6.0)][:, None]
    out = moving_average_in_motion(x, 5, first=2, last=8, shrink_stop=False)
    assert out[3, 0] == pytest.approx(1.0) and out[7, 0] == pytest.approx(4.8) and out.shape == x.shape
    assert out[-1, 0] == pytest.approx(6.0)
    # "shrink": h = 1 there, (4 + 5 + 6) / 3
    assert moving_average_in_motion(x, 5, first=2, last=8)[7, 0] == pytest.approx(5.0)
    with pytest.raises(ValueError, match="shrink, start or hold"):
        PlannerParams(joint_fir_ends="stop")


def test_row_end_stops_without_gear_vibration():
    from dataclasses import replace

    from pathrl.industrial.experiments import select_targets
    from pathrl.industrial.metrics import position_errors
    from pathrl.industrial.trajectories import baseline_program

    # Type 1 (pose 2) stops on the curve at 400 mm/s. Shrinking the joint window at the stop too makes the stop
    # abrupt (setpoint accelerations ~4x) and leaves the gears ringing: ~0.85 mm of error at rest after the last
    # setpoint, which no waypoint governs. The default ("start") smooths the stop: < 0.1 mm at rest.
    t = select_targets(["Type 1 (pose 2)"])[0]
    prog = baseline_program(t)

    def rest_error(mode: str) -> float:
        ctrl = ControllerParams(model="abb", planner=replace(PlannerParams(), joint_fir_ends=mode))
        ex = execute(prog, t.speed, ctrl, seed=0)
        stop = np.nonzero(ex.sdot > 1e-3)[0][-1]
        return float(position_errors(ex.p[stop + 1:], t.p)[0].max())

    assert PlannerParams().joint_fir_ends == "start"
    assert rest_error("start") < 0.1
    assert rest_error("shrink") > 0.5


def test_speed_search_takes_an_ilc_inner_loop():
    from pathrl.industrial.config import check_app
    from pathrl.industrial.experiments import select_targets, speed_iwa
    from pathrl.industrial.iwa_env import IWASettings
    from pathrl.industrial.speed_search import SearchParams, bisection_search
    from pathrl.industrial.trajectories import baseline_program

    t = select_targets(["Type 1 Easy"])[0]
    ctrl, settings = ControllerParams(model="abb"), IWASettings()
    assert speed_iwa(t, ctrl, settings) is None  # the search's default: MPGD
    inner = speed_iwa(t, ctrl, settings, ilc=ILCParams("p", 1.0, k_max=2))
    # one outer step at the row's command: P-type ILC meets all three specs there (results/industrial_abb_table3.md:
    # 0.20 mm, 0.02 deg, speed std 0.2 % after 1 update)
    res = bisection_search(t, t.speed, SearchParams(outer=1), None, ctrl, 0, baseline_program(t), inner)
    assert res.v == pytest.approx(t.speed) and res.best.errors.meets_specs() and res.best.executions <= 3
    base = {"sweep_speeds": [250.0], "waypoints": 100, "zone": 10.0, "policy": ""}
    with pytest.raises(ValueError, match="speed_ilc must be"):
        check_app({**base, "speed_ilc": "x"})
    with pytest.raises(ValueError, match="either policy or speed_ilc"):
        check_app({**base, "speed_ilc": "p", "policy": "runs/x"})


def test_two_fine_points_at_rest_take_a_finite_time():
    from pathrl.industrial.planner import PlannerParams, _time_law

    # samples at 0, 1, 2 mm with the speed 0 at all three (fine points closer than the sampling): each 1 mm takes
    # 2 sqrt(1 / 4000) s = 31.6 ms rest to rest at the TCP acceleration, not 1 mm / 0
    st = _time_law(np.array([0.0, 1.0, 2.0]), np.zeros(3), PlannerParams(fir_s=0.0), 250.0)
    assert abs((len(st) - 1) / 250.0 - 2 * 2 * np.sqrt(1 / 4000.0)) <= 1 / 250.0 and st[-1] == pytest.approx(2.0)
