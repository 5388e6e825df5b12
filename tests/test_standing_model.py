"""The batched model of the free-standing ARMAR-4 (pathrl.sim.standing.AnalyticStanding), hand-checkable: at rest it
stays up, a lean beyond the support polygon falls in the time of a rigid pendulum, a push below the capture
threshold recovers and one above it falls; a batch equals its envs run one by one; its observation has PyBullet's
layout and values on the same postures."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from pathrl.robot.bodies import resting_sole
from pathrl.robot.external import load_robot_by_name
from pathrl.sim.standing import FALL_TILT_RAD, AnalyticStanding, edge_line, polygon_margin, standing_observation

G = 9.81
C = 24  # control setpoints per decision step (0.1 s at 240 Hz)


@pytest.fixture(scope="module")
def robot():
    return load_robot_by_name("armar4_legs")


def _posture(robot, **joints: float) -> torch.Tensor:
    q = torch.zeros(robot.dof, dtype=torch.float64)
    for name, value in joints.items():
        q[robot.joints.index(name)] = value
    return q


def _hold(model: AnalyticStanding, q: torch.Tensor, steps: int, c: int = C):
    """`steps` decision steps of `c` setpoints holding postures q (N, D); the steps' FeedbackStep objects."""
    qs = q[:, None].expand(-1, c, -1)
    return [model.step(qs, torch.zeros_like(qs)) for _ in range(steps)]


def _edge_geometry(model: AnalyticStanding, env: int, normal: tuple[float, float], offset: float):
    """By hand from the reset pose (the centres of mass of the robot's rigid bodies in the world, URDF masses): the
    centre of mass' distance d outside the edge ``normal . x = offset`` and height h, and the bodies' moment of
    inertia about the edge as point masses (the model adds their own inertia tensors: 3.0 % more for ARMAR-4)."""
    p = model.hist[env, -1]
    n = torch.tensor(normal, dtype=torch.float64)
    x, z = p[:, :2] @ n - offset, p[:, 2]
    m = model.mass
    return float((m * x).sum() / m.sum()), float((m * z).sum() / m.sum()), float((m * (x * x + z * z)).sum())


def _pendulum_time(d: float, h: float, inertia: float, mass: float, angle: float) -> float:
    """Time for a rigid body released at rest about a floor edge, I theta'' = M g (d cos theta + h sin theta), to turn
    by `angle` (rad) (fine explicit steps)."""
    th, om, t, dt = 0.0, 0.0, 0.0, 1e-4
    while th < angle:
        om += mass * G * (d * math.cos(th) + h * math.sin(th)) / inertia * dt
        th += om * dt
        t += dt
    return t


def test_zmp_and_support_polygon_by_hand(robot):
    model = AnalyticStanding(robot, 1)
    # one point mass accelerating sideways: the cart-table ZMP x - z a / g; at rest the centre of mass
    p = torch.zeros(1, len(model.links), 3, dtype=torch.float64)
    p[..., 2] = 1.0
    a = torch.zeros_like(p)
    a[..., 0] = 2.0
    torch.testing.assert_close(model.zmp(p, a), torch.tensor([[-2.0 / G, 0.0]], dtype=torch.float64))
    torch.testing.assert_close(model.zmp(p, torch.zeros_like(p)), torch.zeros(1, 2, dtype=torch.float64))
    # a unit square with a point inside on an edge: margins to the nearest edge, outward normal and offset
    square = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.0]]], dtype=torch.float64)
    x = torch.tensor([[[0.5, 0.4], [1.3, 0.5], [0.5, -0.2]]], dtype=torch.float64)
    margin, normal, offset, edge = polygon_margin(square, x)
    torch.testing.assert_close(margin, torch.tensor([[-0.4, 0.3, 0.2]], dtype=torch.float64))
    torch.testing.assert_close(normal, torch.tensor([[[0.0, -1.0], [1.0, 0.0], [0.0, -1.0]]], dtype=torch.float64))
    torch.testing.assert_close(offset, torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64))
    for k in range(3):  # the edge's corners give back its line
        torch.testing.assert_close(edge_line(square, edge[:, k]), (normal[:, k], offset[:, k]))


def test_resting_sole_is_the_largest_downward_facet():
    # a box 0.2 x 0.1 x 0.05 m standing on its bottom face, with a spike on top: the sole is the bottom rectangle
    box = np.array([[x, y, z] for x in (0.0, 0.2) for y in (0.0, 0.1) for z in (0.0, 0.05)] + [[0.1, 0.05, 0.3]])
    poly, normal = resting_sole(box)
    np.testing.assert_allclose(normal, [0.0, 0.0, -1.0], atol=1e-12)
    assert sorted(map(tuple, poly[:, :2].round(6))) == [(0.0, 0.0), (0.0, 0.1), (0.2, 0.0), (0.2, 0.1)]
    area = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
    assert area == pytest.approx(0.02)  # counter-clockwise, no repeated corner


def test_rigid_bodies_keep_mass_centre_of_mass_and_inertia(robot):
    """The 47 massive links of ARMAR-4 with legs merged into 31 rigid bodies: the same mass (72.04 kg), centre of mass
    at any posture and inertia tensor about it as the links one by one (parallel-axis theorem)."""
    from pathrl.robot.bodies import rigid_bodies, urdf_inertials
    from pathrl.robot.kinematics import ForwardKinematics

    fk = ForwardKinematics(robot)
    q = 0.3 * torch.randn(3, robot.dof, dtype=torch.float64, generator=torch.Generator().manual_seed(0))

    def totals(bodies):
        names = list(bodies)
        pos, rot = fk.link_transforms(q, names)
        m = torch.tensor([bodies[n].mass for n in names], dtype=torch.float64)
        p = pos + (rot @ torch.tensor(np.stack([bodies[n].com for n in names]))[:, :, None])[..., 0]
        c = (m[:, None] * p).sum(1) / m.sum()
        d = p - c[:, None]
        tensor = (rot @ torch.tensor(np.stack([bodies[n].inertia for n in names])) @ rot.transpose(-1, -2)).sum(1)
        tensor = tensor + (m[:, None, None] * ((d * d).sum(-1)[..., None, None] * torch.eye(3, dtype=torch.float64)
                                                - d[..., :, None] * d[..., None, :])).sum(1)
        return m.sum(), c, tensor

    links = {k: v for k, v in urdf_inertials(robot.urdf).items() if v.mass > 0.0}
    merged = rigid_bodies(robot)
    assert len(links) == 47 and len(merged) == 31
    for a, b in zip(totals(links), totals(merged), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-9)
    assert float(totals(merged)[0]) == pytest.approx(72.04)


def test_the_soles_are_the_ones_pybullet_stands_on(robot):
    """ARMAR-4's soles: heel at x = -0.051 m, toe at 0.135 m, inner and outer edges at |y| = 0.028 and 0.124 m: the
    contact points PyBullet reports for the robot at rest (docs/lab/armar4_balance.md)."""
    model = AnalyticStanding(robot, 1)
    model.reset(torch.arange(1), _posture(robot)[None])
    sole = model.sole[0].numpy()
    assert sole[:, 0].min() == pytest.approx(-0.051, abs=1e-3) and sole[:, 0].max() == pytest.approx(0.135, abs=1e-3)
    assert np.abs(sole[:, 1]).min() == pytest.approx(0.028, abs=1e-3)
    assert np.abs(sole[:, 1]).max() == pytest.approx(0.124, abs=1e-3)


@pytest.mark.parametrize("name", ["armar4_legs", "armar4"])
def test_at_rest_it_stands_for_ten_seconds(name):
    robot = load_robot_by_name(name)
    model = AnalyticStanding(robot, 1)
    q = _posture(robot)[None]
    model.reset(torch.arange(1), q)
    assert model.reading[0, :3].abs().max() == 0.0 and float(model.reading[0, 7]) < 1e-9  # the URDF pose, as PyBullet
    steps = _hold(model, q, 100)
    tilts = torch.stack([s.values["base_tilt"][0] for s in steps])
    assert not any(bool(s.failed[0]) for s in steps) and bool(model.ok[0])
    assert float(model.theta[0]) == 0.0 and float(model.omega[0]) == 0.0
    # put down flat on its soles, 0.39 deg off the foot frames (PyBullet settles at 0.32-0.37 deg): then no motion
    assert math.degrees(float(tilts[0])) == pytest.approx(0.39, abs=0.02)
    assert float(tilts.max() - tilts.min()) < 1e-12
    assert float(model.margin[0]) < -0.05  # the ZMP (= centre of mass) 6 cm inside the heel edge


def test_a_lean_beyond_the_toes_falls_like_a_rigid_pendulum(robot):
    """Both ankle pitch joints at 0.19 rad lean the body forward 10.9 deg: the centre of mass is 3.7 cm beyond the toe
    edge (the robot is put down on its toes first). The body turns about that edge from rest; it has fallen when the
    pelvis tilt (the lean minus the 0.39 deg of the soles, plus the turn) passes 30 deg."""
    model = AnalyticStanding(robot, 1)
    q = _posture(robot, leg_ank1_joint_r0=0.19, leg_ank1_joint_r1=0.19)[None]
    model.reset(torch.arange(1), q)
    d, h, inertia = _edge_geometry(model, 0, (1.0, 0.0), float(model.sole[0, :, 0].max()))
    assert d == pytest.approx(0.037, abs=0.002)
    first = _hold(model, q, 1)[0]
    lean = float(first.values["base_tilt"][0]) - float(model.theta[0])  # the pelvis tilt of the posture, put down
    assert math.degrees(lean) == pytest.approx(math.degrees(0.19) - 0.39, abs=0.05)
    expected = _pendulum_time(d, h, inertia, model.total, FALL_TILT_RAD - lean)  # 0.99 s
    steps = [first, *_hold(model, q, 30)]
    fell = next(k for k, s in enumerate(steps) if bool(s.failed[0]))  # in step k: (k * 0.1 s, (k + 1) * 0.1 s]
    assert fell * 0.1 - 0.01 < expected * 1.015 < (fell + 1) * 0.1 + 0.01  # + the links' own inertia (3 %: t 1.5 %)
    assert float(model.edge_n[0, 0]) == pytest.approx(1.0)  # about the toe edge
    assert float(model.reading[0, 0]) > 0.3  # the pelvis went forward


@pytest.mark.parametrize("direction,normal,edge", [((1.0, 0.0), (1.0, 0.0), "toe"),
                                                  ((-1.0, 0.0), (-1.0, 0.0), "heel")])
def test_a_push_below_the_capture_threshold_recovers_and_above_it_falls(robot, direction, normal, edge):
    """An initial tip rate omega0 about an edge of the robot at rest (CoM at distance l from the edge, h above it):
    it comes over the edge iff its energy I omega0^2 / 2 lifts the centre of mass by l - h, i.e. omega0 above
    omega_c = sqrt(2 M g (l - h) / I) (0.38 rad/s about the toe, 0.20 about the heel). 0.85 omega_c tips up to where
    gravity has taken its energy, lands and stands; 1.15 omega_c falls."""
    model = AnalyticStanding(robot, 2)
    q = _posture(robot)[None].expand(2, -1)
    model.reset(torch.arange(2), q)
    _hold(model, q, 1)
    sole = model.sole[0].numpy() @ np.asarray(normal)
    d, h, inertia = _edge_geometry(model, 0, normal, float(sole.max()))
    ell = math.hypot(d, h)
    omega_c = math.sqrt(2.0 * model.total * G * (ell - h) / inertia)
    assert omega_c == pytest.approx(0.38 if edge == "toe" else 0.20, abs=0.02)
    model.push(torch.arange(2), torch.tensor([0.85 * omega_c, 1.15 * omega_c], dtype=torch.float64), direction)
    assert model.edge_n[:, 0].tolist() == pytest.approx([normal[0]] * 2)
    # the highest tip of the recovering env, sampled at every model instant (6 setpoints), against energy by hand:
    # I omega0^2 / 2 = M g (l cos(phi0 - theta) - h) with phi0 = atan(-d / h) (the CoM behind the edge)
    peak, fell_at = 0.0, None
    for k in range(150):
        out = model.step(*(x[:, None].expand(-1, 6, -1) for x in (q, torch.zeros_like(q))))
        peak = max(peak, float(model.theta[0]))
        if fell_at is None and bool(out.failed[1]):
            fell_at = k
    phi0 = math.atan2(-d, h)
    lift = (0.85 * omega_c) ** 2 * inertia / (2.0 * model.total * G)
    assert peak == pytest.approx(phi0 - math.acos((h + lift) / ell), rel=0.05)
    assert bool(model.ok[0]) and float(model.theta[0]) == 0.0 and float(model.omega[0]) == 0.0  # landed, at rest
    assert math.degrees(float(model.reading[0, 7])) == pytest.approx(0.39, abs=0.02)
    assert not bool(model.ok[1]) and fell_at is not None and float(model.theta[1]) == pytest.approx(math.pi / 2)


def test_one_knee_bent_alone_tips_the_body_back_onto_the_other_heel(robot):
    """Knee r0 bent by a = 0.05 rad alone (2 s, then held): the legs disagree, the body hangs off foot r0 (the stance
    with the lower centre of mass: foot r1 rocks back onto its heel instead of onto foot r0's toe) and leans back by
    a (2.86 deg) plus the soles' 0.39 deg; foot r1's toe corners leave the floor. PyBullet: 3.06 deg back (its
    motors give way a little sideways too: 1.2 deg). Both knees bent alike: both feet flat, the same lean."""
    from pathrl.baselines.balance import lean_vector

    one = _posture(robot, leg_knee_joint_r0=0.05)
    both = _posture(robot, leg_knee_joint_r0=0.05, leg_knee_joint_r1=0.05)
    model = AnalyticStanding(robot, 2)
    model.reset(torch.arange(2), torch.zeros(2, robot.dof, dtype=torch.float64))
    target = torch.stack([one, both])
    for k in range(30):
        qs, _ = _smooth(np.ones(1), 3.0)
        qs = torch.as_tensor(qs[k * C:(k + 1) * C, 0])[None, :, None] * target[:, None]
        model.step(qs, torch.zeros_like(qs))
    lean = np.degrees(lean_vector(model.reading[:, 3:7]).numpy())
    np.testing.assert_allclose(lean[:, 0], -(math.degrees(0.05) + 0.39), atol=0.02)
    np.testing.assert_allclose(lean[:, 1], 0.0, atol=0.02)
    r1_toe = (model.sole_foot == 1) & (model.sole_local[:, 2].abs() > 0.1)  # toe corners, far from the ankle
    assert r1_toe.sum() == 2 and not model.contact[0, r1_toe].any() and model.contact[0, ~r1_toe].all()
    assert model.contact[1].all() and model.ok.all() and (model.theta == 0).all()


def _motion(robot, n: int, steps: int) -> torch.Tensor:
    """Setpoints (n, steps, C, D): env i swings its torso, arms and (for odd i) ankles and knees at its own amplitude
    and frequency from the zero posture; the larger ones fall."""
    t = torch.arange(1, steps * C + 1, dtype=torch.float64) / 240.0
    q = torch.zeros(n, steps * C, robot.dof, dtype=torch.float64)
    for i in range(n):
        amp, freq = 0.2 + 0.15 * i, 0.5 + 0.3 * i
        ramp = (t / 1.0).clamp(max=1.0)
        wave = amp * ramp * torch.sin(2 * math.pi * freq * t)
        for name, gain in (("torso_pitch_joint", 1.0), ("arm_sho1_joint_r0", 2.0), ("arm_sho2_joint_r1", 2.5)):
            q[i, :, robot.joints.index(name)] = gain * wave
        if i % 2:
            for name in ("leg_ank1_joint_r0", "leg_ank1_joint_r1"):
                q[i, :, robot.joints.index(name)] = 0.3 * wave
            for name in ("leg_knee_joint_r0", "leg_knee_joint_r1"):
                q[i, :, robot.joints.index(name)] = 0.5 * wave.abs()
    return q.reshape(n, steps, C, robot.dof)


def test_a_batch_equals_its_envs_one_by_one(robot):
    n, steps = 4, 40
    q = _motion(robot, n, steps)
    batch = AnalyticStanding(robot, n)
    batch.reset(torch.arange(n), torch.zeros(n, robot.dof, dtype=torch.float64))
    singles = [AnalyticStanding(robot, 1) for _ in range(n)]
    for s in singles:
        s.reset(torch.arange(1), torch.zeros(1, robot.dof, dtype=torch.float64))
    for k in range(steps):
        out = batch.step(q[:, k], torch.zeros_like(q[:, k]))
        for i, s in enumerate(singles):
            one = s.step(q[i:i + 1, k], torch.zeros_like(q[i:i + 1, k]))
            torch.testing.assert_close(out.obs[i:i + 1], one.obs, rtol=0, atol=1e-9)
            assert bool(out.failed[i]) == bool(one.failed[0])
            assert float(batch.theta[i]) == pytest.approx(float(s.theta[0]), abs=1e-9)
    assert (~batch.ok).any() and batch.ok.any()  # some fell, some stood
    assert (batch.theta > 0).any()


def test_reset_of_some_envs_leaves_the_others(robot):
    q = _motion(robot, 2, 5)
    model = AnalyticStanding(robot, 2)
    model.reset(torch.arange(2), torch.zeros(2, robot.dof, dtype=torch.float64))
    for k in range(5):
        model.step(q[:, k], q[:, k])
    before = model.reading[1].clone()
    model.reset(torch.tensor([0]), torch.zeros(1, robot.dof, dtype=torch.float64))
    assert torch.equal(model.reading[1], before) and model.reading[0, :3].abs().max() == 0.0


def _smooth(target: np.ndarray, seconds: float, move: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Control setpoints (T, D) and velocities of a minimum-jerk move from 0 to `target` in `move` s, then held."""
    t = np.arange(1, int(round(seconds * 240)) + 1) / 240.0
    s = np.clip(t / move, 0.0, 1.0)
    return (10 * s**3 - 15 * s**4 + 6 * s**5)[:, None] * target, \
        ((30 * s**2 - 60 * s**3 + 30 * s**4) / move * (t < move))[:, None] * target


def test_pybullet_reads_the_same_observation_on_the_same_postures(robot):
    """PyBulletStanding (the evaluation backend) and the model on the same held postures (1 s) and slow moves (2 s,
    then 1 s held): the same 8 observation columns within 0.05 (pelvis offset, 5.8 mm), 0.005 (quaternion) and
    0.08 (tilt, 0.29 deg: PyBullet's motors give a little with the load). One knee bent alone by 0.05 rad: the same
    tilt (3.3 deg; PyBullet's motors give way further, it also rolls 1.2 deg, turns 5 deg about the vertical and
    moves 1.5 cm: only the tilt is compared). Bending the knees 0.3 rad tips both over backwards (the centre of mass
    goes behind the heels)."""
    from pathrl.sim.vec import PyBulletStanding

    held = [_posture(robot), _posture(robot, torso_pitch_joint=-0.3, arm_sho1_joint_r0=0.5),
            _posture(robot, arm_sho1_joint_r0=0.6, arm_sho1_joint_r1=0.6, torso_pitch_joint=0.4)]
    moves = [_posture(robot, leg_ank1_joint_r0=-0.04, leg_ank1_joint_r1=-0.04),
             _posture(robot, leg_ank1_joint_r0=0.05, leg_ank1_joint_r1=0.05), _posture(robot, leg_knee_joint_r0=0.05),
             _posture(robot, leg_knee_joint_r0=0.3, leg_knee_joint_r1=0.3)]
    n = len(held) + len(moves)
    start = torch.stack(held + [torch.zeros(robot.dof, dtype=torch.float64)] * len(moves))
    setpoints = torch.zeros(n, 30 * C, robot.dof, dtype=torch.float64)
    velocities = torch.zeros_like(setpoints)
    setpoints[: len(held)] = start[: len(held), None]
    for i, target in enumerate(moves):
        qs, vs = _smooth(target.numpy(), 3.0)
        setpoints[len(held) + i], velocities[len(held) + i] = torch.as_tensor(qs), torch.as_tensor(vs)
    pool = PyBulletStanding(robot, n, seed=0, workers=1)
    model = AnalyticStanding(robot, n)
    try:
        ids = torch.arange(n)
        pool.reset(ids, start)
        model.reset(ids, start)
        torch.testing.assert_close(model.observe(), pool.observe(), rtol=0, atol=1e-6)  # the URDF pose at reset
        for k in range(30):
            sl = slice(k * C, (k + 1) * C)
            a, b = pool.step(setpoints[:, sl], velocities[:, sl]), model.step(setpoints[:, sl], velocities[:, sl])
            if k == 19:  # the moves have just ended; the knees are falling
                assert b.obs.shape == a.obs.shape == (n, 8)
                gap = (b.obs - a.obs).abs()[:-1]
                assert gap[:-1, :3].max() < 0.05 and gap[:-1, 3:7].max() < 0.005 and gap[:, 7].max() < 0.08, gap
        assert pool.ok[:-1].all() and model.ok[:-1].all()
        assert not pool.ok[-1] and not model.ok[-1]  # the bent knees fell in both
        assert float(pool.reading[-1, 0]) < -0.3 and float(model.reading[-1, 0]) < -0.3  # backwards
        torch.testing.assert_close(standing_observation(model.reading), model.observe())
    finally:
        pool.close()
