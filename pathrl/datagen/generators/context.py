"""Per-process generator context (FK, collision checker, generation limits) and the seeded random streams."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from pathrl.robot.model import RobotSpec, load_robot

__all__ = ["GenerationError", "GeneratorContext", "chunk_rngs", "process_context"]


class GenerationError(RuntimeError):
    """A generator could not produce the requested paths (e.g. no valid start configurations)."""



class GeneratorContext:
    """FK, collision checker and limits of one robot, built once per process."""

    def __init__(self, robot_cfg: Mapping[str, Any]):
        from pathrl.robot.collision import CollisionChecker
        from pathrl.robot.kinematics import ForwardKinematics

        self.spec: RobotSpec = load_robot(robot_cfg)
        self.fk = ForwardKinematics(self.spec)
        self.checker = CollisionChecker(self.spec)
        self._limits = None
        self.set_margin(0.0)
        self.pidx = torch.as_tensor(self.spec.path_index)

    def set_margin(self, margin: float) -> None:
        """Generate motions within the position limits shrunk by `margin` (rad or m) on each side."""
        if getattr(self, "margin", None) == margin:
            return
        self.margin = float(margin)
        lim = self.spec.pos_limits + np.array([margin, -margin])
        if np.any(lim[:, 0] >= lim[:, 1]):
            raise GenerationError(f"limit_margin {margin} leaves an empty position range")
        self.gen_limits = lim
        self.lo = torch.as_tensor(lim[:, 0])
        self.hi = torch.as_tensor(lim[:, 1])
        self._limits = None

    def reachable_grid(self, n: int = 20_000, voxel: float = 0.05) -> tuple[np.ndarray, float]:
        """Occupancy (T, nx, ny, nz) of the workspace box by each TCP over n random configurations."""
        if getattr(self, "_grid", None) is None:
            rng = np.random.default_rng(12345)
            q = rng.uniform(self.spec.pos_limits[:, 0], self.spec.pos_limits[:, 1], size=(n, self.spec.dof))
            pos = self.fk.tcp_positions_np(q)  # (n, T, 3)
            ws = self.spec.workspace
            shape = np.maximum(np.ceil((ws[:, 1] - ws[:, 0]) / voxel).astype(int), 1)
            grid = np.zeros((pos.shape[1], *shape), dtype=bool)
            idx = np.floor((pos - ws[:, 0]) / voxel).astype(int)
            inside = np.all((idx >= 0) & (idx < shape), axis=-1)
            for t in range(pos.shape[1]):
                i = idx[inside[:, t], t]
                grid[t, i[:, 0], i[:, 1], i[:, 2]] = True
            self._grid = grid
        return self._grid, voxel

    def sample_targets(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """n Cartesian targets per TCP (n, T, 3), uniform in the workspace box restricted to voxels
        that the TCP reached in random configurations (skips hopeless IK problems)."""
        grid, voxel = self.reachable_grid()
        ws = self.spec.workspace
        out = np.empty((n, grid.shape[0], 3))
        for t in range(grid.shape[0]):
            got = 0
            for _ in range(1000):
                x = rng.uniform(ws[:, 0], ws[:, 1], size=(4 * (n - got) + 8, 3))
                i = np.minimum(np.floor((x - ws[:, 0]) / voxel).astype(int), np.array(grid.shape[1:]) - 1)
                x = x[grid[t, i[:, 0], i[:, 1], i[:, 2]]][: n - got]
                out[got : got + len(x), t] = x
                got += len(x)
                if got == n:
                    break
            else:
                raise GenerationError(f"{self.spec.name}: TCP {t} never reaches its workspace box")
        return out

    @property
    def limits(self):
        """The robot's JointLimits within the generation position limits (built on first use)."""
        if self._limits is None:
            from dataclasses import replace

            from pathrl.limits.feasible import JointLimits

            self._limits = JointLimits.from_robot(replace(self.spec, pos_limits=self.gen_limits))
        return self._limits

    def in_collision(self, q: np.ndarray | torch.Tensor) -> np.ndarray:
        """Per configuration (N, D) whether the robot collides (N,) bool."""
        q = q.detach().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q)
        if len(q) == 0:
            return np.zeros(0, dtype=bool)
        return np.asarray(self.checker.in_collision(np.ascontiguousarray(q, dtype=np.float64)), dtype=bool)

    def in_workspace(self, q: np.ndarray | torch.Tensor) -> np.ndarray:
        """Per configuration (N, D) whether every TCP is inside the workspace box (N,) bool."""
        q = q.detach().cpu().numpy() if isinstance(q, torch.Tensor) else np.asarray(q)
        if len(q) == 0:
            return np.zeros(0, dtype=bool)
        pos = self.fk.tcp_positions_np(q)  # (N, T, 3)
        ws = self.spec.workspace
        return np.all((pos >= ws[:, 0]) & (pos <= ws[:, 1]), axis=(1, 2))


_CONTEXTS: dict[str, GeneratorContext] = {}


def process_context(robot_cfg: Mapping[str, Any]) -> GeneratorContext:
    """The context of `robot_cfg`, built once per process (the last robot's only)."""
    key = repr(sorted(robot_cfg.items()))
    if key not in _CONTEXTS:
        torch.set_num_threads(1)
        _CONTEXTS.clear()
        _CONTEXTS[key] = GeneratorContext(robot_cfg)
    return _CONTEXTS[key]


def chunk_rngs(seed: int, split_id: int, chunk: int) -> tuple[np.random.Generator, torch.Generator]:
    """The numpy and torch generators of chunk `chunk` of split `split_id`: SeedSequence(seed, (split, chunk))."""
    ss = np.random.SeedSequence(int(seed), spawn_key=(split_id, chunk))
    rng = np.random.default_rng(ss)
    tgen = torch.Generator().manual_seed(int(ss.generate_state(1, np.uint64)[0] & 0x7FFF_FFFF_FFFF_FFFF))
    return rng, tgen


