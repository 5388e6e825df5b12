"""Mass and contact geometry of a robot's links, read from its URDF (no simulator): what a model of the whole
body needs besides forward kinematics.

* :func:`urdf_inertials`: each link's mass (kg), centre of mass (m, link frame) and inertia tensor about it
  (kg m^2, link axes), from the ``<inertial>`` elements (the values PyBullet loads).
* :func:`collision_vertices`: the vertices (m, link frame) of a link's collision geometry: binary or ASCII STL
  meshes (with their ``scale``) and boxes (8 corners); other primitives are skipped.
* :func:`resting_sole`: the face a convex body rests on when put down on a floor: the downward facet of the
  vertices' convex hull with the largest area (a simulator collides a mesh as its convex hull).
* :func:`rigid_bodies`: the links that move together (joined by joints the robot does not control) merged into one
  body each: mass, centre of mass and inertia in the frame of the body's first link.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pathrl.robot.kinematics import ForwardKinematics, parse_urdf_joints, rpy_to_matrix
from pathrl.robot.model import RobotSpec

__all__ = ["LinkInertial", "collision_vertices", "read_stl", "resolve_mesh", "resting_sole", "rigid_bodies",
           "urdf_inertials"]


@dataclass(frozen=True)
class LinkInertial:
    """One link's inertial: mass (kg), centre of mass `com` (3,) in m and inertia (3, 3) in kg m^2 about it, both
    in the link frame."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


def _vec(el: ET.Element | None, key: str, default: tuple[float, ...]) -> np.ndarray:
    text = None if el is None else el.get(key)
    return np.asarray(default if text is None else [float(v) for v in text.replace(",", " ").split()], dtype=float)


def urdf_inertials(urdf: str | Path) -> dict[str, LinkInertial]:
    """Every link's :class:`LinkInertial` by name (a link without ``<inertial>`` has mass 0)."""
    out = {}
    for link in ET.parse(str(urdf)).getroot().findall("link"):
        el = link.find("inertial")
        if el is None:
            out[link.get("name")] = LinkInertial(0.0, np.zeros(3), np.zeros((3, 3)))
            continue
        origin, mass, inertia = el.find("origin"), el.find("mass"), el.find("inertia")
        rot = rpy_to_matrix(_vec(origin, "rpy", (0.0, 0.0, 0.0)))
        i = {k: float(inertia.get(k, 0.0)) if inertia is not None else 0.0
             for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        tensor = np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]],
                           [i["ixz"], i["iyz"], i["izz"]]])
        out[link.get("name")] = LinkInertial(float(mass.get("value")) if mass is not None else 0.0,
                                             _vec(origin, "xyz", (0.0, 0.0, 0.0)), rot @ tensor @ rot.T)
    return out


def resolve_mesh(urdf: Path, filename: str) -> Path:
    """The file of a URDF mesh reference: ``package://NAME/rest`` is looked up against the URDF's directory and its
    ancestors (as PyBullet does), a relative path against the URDF's directory."""
    if filename.startswith("package://"):
        rest = filename.removeprefix("package://")
        for base in (urdf.parent, *urdf.parents):
            if (base / rest).is_file():
                return base / rest
        raise FileNotFoundError(f"{urdf.name}: mesh {filename} not found")
    path = Path(filename)
    return path if path.is_absolute() else urdf.parent / path


def read_stl(path: Path) -> np.ndarray:
    """Vertices (3 per triangle, (3T, 3)) of a binary or ASCII STL file."""
    data = path.read_bytes()
    count = int(np.frombuffer(data[80:84], dtype="<u4")[0]) if len(data) >= 84 else -1
    if len(data) == 84 + 50 * count:  # binary: 80-byte header, count, 50 bytes per triangle
        rec = np.frombuffer(data[84:], dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
        return rec["v"].reshape(-1, 3).astype(np.float64)
    words = data.decode("ascii", errors="replace").split()
    idx = [i for i, w in enumerate(words) if w == "vertex"]
    if not idx:
        raise ValueError(f"{path}: neither a binary nor an ASCII STL file")
    return np.array([[float(words[i + k]) for k in (1, 2, 3)] for i in idx])


def collision_vertices(urdf: str | Path, link: str) -> np.ndarray:
    """Vertices (V, 3) of the collision geometry of `link` in its link frame (m): STL meshes and boxes."""
    urdf = Path(urdf)
    el = next((x for x in ET.parse(str(urdf)).getroot().findall("link") if x.get("name") == link), None)
    if el is None:
        raise ValueError(f"{urdf.name}: no link {link!r}")
    parts = []
    for col in el.findall("collision"):
        origin, geom = col.find("origin"), col.find("geometry")
        rot, pos = rpy_to_matrix(_vec(origin, "rpy", (0.0, 0.0, 0.0))), _vec(origin, "xyz", (0.0, 0.0, 0.0))
        mesh, box = geom.find("mesh"), geom.find("box")
        if mesh is not None and mesh.get("filename", "").lower().endswith(".stl"):
            v = read_stl(resolve_mesh(urdf, mesh.get("filename"))) * _vec(mesh, "scale", (1.0, 1.0, 1.0))
        elif box is not None:
            half = _vec(box, "size", (0.0, 0.0, 0.0)) / 2.0
            v = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        else:
            continue
        parts.append(v @ rot.T + pos)
    if not parts:
        raise ValueError(f"{urdf.name}: link {link!r} has no STL mesh or box collision geometry")
    return np.concatenate(parts)


def resting_sole(vertices: np.ndarray, max_tilt_deg: float = 10.0, plane_tol: float = 2e-5,
                 corner_tol: float = 2e-3) -> tuple[np.ndarray, np.ndarray]:
    """The sole a body with these vertices (V, 3) stands on: the facet plane of their convex hull whose outward normal
    points down (within `max_tilt_deg` of -z) with the largest area (coplanar facets merged).

    Returns ``(polygon, normal)``: the corners of the hull vertices on that plane (within `plane_tol` m), (S, 3),
    counter-clockwise seen from above, a corner dropped while it lies within `corner_tol` m of the line through its
    neighbours (a slightly smaller polygon with fewer corners); and the plane's outward unit normal (3,) (about -z)."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(vertices)
    normals, offsets = hull.equations[:, :3], hull.equations[:, 3]
    down = np.flatnonzero(normals[:, 2] < -np.cos(np.radians(max_tilt_deg)))
    if len(down) == 0:
        raise ValueError(f"no hull facet faces down within {max_tilt_deg} deg")
    tri = vertices[hull.simplices[down]]  # (F, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    total = np.array([area[(np.abs(normals[down] - normals[f]).max(axis=1) < 1e-3)
                           & (np.abs(offsets[down] - offsets[f]) < 1e-4)].sum() for f in down])
    best = down[int(np.argmax(total))]
    normal = normals[best]
    on = vertices[np.unique(hull.vertices[np.abs(vertices[hull.vertices] @ normal + offsets[best]) < plane_tol])]
    poly = on[ConvexHull(on[:, :2]).vertices] if len(on) > 3 else on  # counter-clockwise
    while len(poly) > 3:
        prev, nxt = np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0)
        chord = nxt[:, :2] - prev[:, :2]
        rel = poly[:, :2] - prev[:, :2]
        dist = np.abs(chord[:, 0] * rel[:, 1] - chord[:, 1] * rel[:, 0]) / np.linalg.norm(chord, axis=1)
        if dist.min() >= corner_tol:
            break
        poly = np.delete(poly, int(np.argmin(dist)), axis=0)
    return poly, normal


def rigid_bodies(robot: RobotSpec) -> dict[str, LinkInertial]:
    """The robot's massive links merged into rigid bodies: links joined by joints not in ``robot.joints`` (fixed, or
    frozen at 0) move as one. Keyed by each body's first link (the child of its controlled joint, or the URDF root);
    the :class:`LinkInertial` (mass, centre of mass, inertia about it by the parallel-axis theorem) is in that link's
    frame. Bodies without mass are left out."""
    root, joints = parse_urdf_joints(robot.urdf)
    controlled = set(robot.joints)

    def head(link: str) -> str:
        while link != root and joints[link].name not in controlled:
            link = joints[link].parent
        return link

    inert = {k: v for k, v in urdf_inertials(robot.urdf).items() if v.mass > 0.0}
    groups: dict[str, list[str]] = {}
    for link in inert:
        groups.setdefault(head(link), []).append(link)
    names = sorted({*groups, *(x for g in groups.values() for x in g)})
    pos, rot = ForwardKinematics(robot).link_transforms(np.zeros((1, robot.dof)), names)
    frame = {n: (rot[0, i].numpy(), pos[0, i].numpy()) for i, n in enumerate(names)}  # zero posture
    out = {}
    for first, members in groups.items():
        r0, p0 = frame[first]
        mass = sum(inert[m].mass for m in members)
        coms = {m: r0.T @ (frame[m][0] @ inert[m].com + frame[m][1] - p0) for m in members}  # in the first frame
        com = sum(inert[m].mass * coms[m] for m in members) / mass
        tensor = np.zeros((3, 3))
        for m in members:
            r = r0.T @ frame[m][0]
            d = coms[m] - com
            tensor += r @ inert[m].inertia @ r.T + inert[m].mass * (d @ d * np.eye(3) - np.outer(d, d))
        out[first] = LinkInertial(mass, com, tensor)
    return out
