"""Free-standing ARMAR-4 scene: it stands still when left alone, falls when pushed, sensors are relative to reset."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pathrl.robot.external import load_robot_by_name
from pathrl.sim.humanoid import StandingScene


@pytest.fixture(scope="module", params=["armar4", "armar4_legs"])
def scene(request):
    with StandingScene(load_robot_by_name(request.param)) as sc:
        yield sc


def hold(scene, q, seconds):
    n = int(round(seconds / scene.control_dt))
    scene.follow(np.tile(q, (n, 1)), np.zeros((n, len(q))))


def test_sensors_start_at_zero_and_robot_stands(scene):
    q0 = np.zeros(len(scene.joint_ids))
    scene.reset(q0)
    np.testing.assert_allclose(scene.pelvis_offset(), 0.0, atol=1e-12)
    assert scene.tilt_deg() < 0.5
    assert scene.pelvis_pose()[0][2] > 0.9  # pelvis about 1 m above the floor
    hold(scene, q0, 2.0)
    assert not scene.fallen()
    assert scene.tilt_deg() < 2.0 and np.linalg.norm(scene.pelvis_offset()) < 0.02


def test_push_makes_it_fall(scene):
    q0 = np.zeros(len(scene.joint_ids))
    scene.reset(q0)
    hold(scene, q0, 0.2)
    scene.push((400.0, 0.0, 0.0), 0.3)
    fell = False
    for _ in range(30):
        hold(scene, q0, 0.1)
        fell = fell or scene.fallen()
    assert fell
    assert scene.pelvis_offset()[0] > 0.2  # fell forward, in the push direction


@pytest.mark.parametrize("robot", ["armar4_legs", "armar6"])
def test_scenes_load_collision_geometry_only(robot, tmp_path):
    """Visual meshes are dropped (memory), every collision mesh is kept and resolves to an existing file."""
    import re
    import xml.etree.ElementTree as ET

    from pathrl.sim.scene import collision_only_urdf

    urdf = load_robot_by_name(robot).urdf
    text = collision_only_urdf(urdf)
    original = ET.parse(urdf).getroot()
    stripped = ET.fromstring(text)
    assert not list(stripped.iter("visual"))
    assert len(list(stripped.iter("collision"))) == len(list(original.iter("collision"))) > 0
    files = re.findall(r'filename="([^"]+)"', text)
    assert files and all(f.startswith("/") and Path(f).is_file() for f in files)
    local = tmp_path / "r.urdf"  # relative and package:// paths, resolved against the file's location
    (tmp_path / "pkg" / "m").mkdir(parents=True)
    (tmp_path / "pkg" / "m" / "a.stl").write_text("solid a\nendsolid a\n")
    local.write_text('<robot name="r"><link name="l"><visual><geometry><mesh filename="pkg/m/a.stl"/></geometry>'
                     '</visual><collision><geometry><mesh filename="package://pkg/m/a.stl"/></geometry></collision>'
                     '<collision><geometry><mesh filename="pkg/m/a.stl"/></geometry></collision></link></robot>')
    assert re.findall(r'filename="([^"]+)"', collision_only_urdf(local)) == [str(tmp_path / "pkg/m/a.stl")] * 2
