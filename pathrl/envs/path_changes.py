"""Path changes during training: the evaluation's online path adjustment (:mod:`pathrl.eval.path_change`) as part
of the episodes PPO learns from.

Rule (the evaluation's protocol, per episode): when an episode starts, it is chosen for a change with probability
``fraction`` and gets a switch time drawn uniformly from ``switch_range`` seconds (rounded to decision steps, as
the evaluation rounds). At that step, if the episode is still running and not braking, the rest of its segment is
replaced by its branch (:func:`pathrl.paths.branch.branch_knots`: from the robot, the remaining knots shifted by
a random joint offset ramped in over some arc length) through :meth:`PathTrackingEnv.replace_path`; the robot
keeps its position, velocity and acceleration, so every limit holds as on any path. The offset's direction is
uniform on the sphere, its size and ramp one of the (``offsets``, ``ramps``) variants, uniformly (defaults: the
evaluation's gentle and sharp variants). So each episode changes at most once, at the times the evaluation
changes; a random switch time per episode rather than a per-step probability, since the latter would put most
changes early in long episodes and sometimes several in one. Every draw comes from the env's own generator.

The branches live in ``slots`` extra rows of the env's path bank (the env samples new episodes only from the
first ``sample_paths`` rows); an episode on a branch holds its slot until it ends. When no slot is free, or too
little of the segment is left, that episode's change is skipped (logged). Branch knots are the path's own
(already placed) knots, shifted; they are not re-placed by the knot strategy as the deployed follower does.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import torch
from tensordict import TensorDict
from torch import Tensor

from pathrl.envs.path_change_cfg import PathChangeCfg
from pathrl.paths.branch import BranchShape, BranchStart, branch_knots, dedupe_padded, tabulate_batch

__all__ = ["PathChangeCfg", "PathChanges", "with_path_changes"]


def _with_slots(paths, slots: int, extra_knots: int, extra_rows: int):
    """The path bank with `slots` more rows (copies of path 0) and room for `extra_knots` knots and `extra_rows`
    table rows more, padded as build_pathset pads."""
    def grow(t: Tensor, extra: int) -> Tensor:
        return torch.cat([t, t[:, -1:].expand(-1, extra, *t.shape[2:])], dim=1) if extra else t

    def add(t: Tensor) -> Tensor:
        return torch.cat([t, t[:1].expand(slots, *t.shape[1:])]).contiguous()

    return replace(paths, names=paths.names + tuple(f"branch{i}" for i in range(slots)),
                   knots=add(grow(paths.knots, extra_knots)), knot_s=add(grow(paths.knot_s, extra_knots)),
                   num_knots=add(paths.num_knots), length=add(paths.length),
                   table=add(grow(paths.table, extra_rows)))


class PathChanges:
    """A :class:`~pathrl.envs.tracking.PathTrackingEnv` whose episodes' paths change once at a random time (module
    docstring). Everything else is the wrapped env's."""

    def __init__(self, env: Any, cfg: PathChangeCfg):
        if not getattr(env.cfg, "autoreset", True):
            raise ValueError("path_change: needs an env that resets its own episodes (training)")
        self.env, self.cfg = env, cfg
        self.base = env.paths.num_paths
        env.paths = _with_slots(env.paths, cfg.slots, 2, int(2.0 / env.paths.table_step))
        env.sample_paths = self.base
        n, dev = env.num_envs, env.device
        self.switch_step = torch.zeros(n, dtype=torch.long, device=dev)
        self.pending = torch.zeros(n, dtype=torch.bool, device=dev)  # this episode still changes
        self.changed = torch.zeros(n, dtype=torch.bool, device=dev)  # this episode has changed
        knots = env.paths.knots
        self.slot_knots = knots[self.base:].clone()  # the branches' knots: the state a resume needs
        self.slot_count = env.paths.num_knots[self.base:].clone()
        self._built = [self.slot_knots]  # tables built from these knots (a restore replaces them)
        self.pos_limits = env.limits.pos.index_select(0, env.path_index)
        self._schedule(torch.arange(n, device=dev))

    def __getattr__(self, name: str):
        return getattr(self.env, name)

    def reset(self) -> TensorDict:
        """Reset all envs and schedule their path changes; the observations."""
        obs = self.env.reset()
        self._schedule(torch.arange(self.env.num_envs, device=self.env.device))
        return obs

    def _schedule(self, ids: Tensor) -> None:
        """New episodes `ids`: whether and when their path changes."""
        g, dev, k = self.env.generator, self.env.device, len(ids)
        lo, hi = self.cfg.switch_range
        u = torch.rand(2, k, generator=g, device=dev, dtype=torch.float64)
        self.switch_step[ids] = torch.round((lo + (hi - lo) * u[0]) / self.env.cfg.dt).long()
        self.pending[ids] = u[1] < self.cfg.fraction
        self.changed[ids] = False

    def _sync_tables(self) -> None:
        """Rebuild the slots' tables when their knots were replaced (a resumed run restores the knots only)."""
        if self._built[0] is self.slot_knots:
            return
        seg = self.env.seg_path
        used = torch.unique(seg[seg >= self.base] - self.base)  # the others are written when next used
        if len(used):
            self._write(used, self.slot_knots[used], self.slot_count[used])
        self._built = [self.slot_knots]

    def _write(self, slots: Tensor, knots: Tensor, count: Tensor) -> Tensor:
        """Tabulate branches into path-bank rows base + `slots`; returns which fit the table."""
        p = self.env.paths
        tab = tabulate_batch(knots, count, p.table_step, p.table.shape[1], self.cfg.arc_step, extrapolate=True)
        rows = self.base + slots
        p.knots[rows], p.knot_s[rows], p.num_knots[rows] = knots, tab["knot_s"], count
        p.length[rows], p.table[rows] = tab["length"], tab["table"]
        self.slot_knots[slots], self.slot_count[slots] = knots, count
        return tab["fits"]

    def step(self, actions: Tensor) -> tuple[TensorDict, Tensor, Tensor, dict]:
        """Step the wrapped env, reschedule ended episodes and change due paths; (obs, rewards (N,), dones (N,),
        extras)."""
        self._sync_tables()
        obs, rew, dones, extras = self.env.step(actions)
        ended = dones.nonzero().squeeze(1)
        log = extras.setdefault("log", {})
        if len(ended):
            log["PathChange/changed_episodes"] = self.changed[ended].float().mean()
            self._schedule(ended)
        n = self._change()
        log["PathChange/changes_per_step"] = float(n)
        return (self.env.get_observations() if n else obs), rew, dones, extras

    def _change(self) -> int:
        """Branch the paths of the envs whose switch time is now (module docstring); returns how many changed."""
        env = self.env
        due = self.pending & (env.episode_length_buf == self.switch_step)
        if not bool(due.any()):
            return 0
        self.pending &= ~due
        ids = due.nonzero().squeeze(1)
        seg = env.seg_path[ids]
        held = env.seg_path[env.seg_path >= self.base] - self.base
        free = (torch.bincount(held, minlength=self.cfg.slots) == 0).nonzero().squeeze(1)
        ids, seg = ids[: len(free)], seg[: len(free)]  # no free slot: skipped
        ids, seg = ids[~env.braking[ids]], seg[~env.braking[ids]]
        if not len(ids):
            return 0
        knots, count = self._branches(ids, seg)
        ok = count >= 2
        ids, knots, count = ids[ok], knots[ok], count[ok]
        if not len(ids):
            return 0
        slots = free[: len(ids)]
        fits = self._write(slots, knots, count)
        ids, slots = ids[fits], slots[fits]
        env.replace_path(ids, self.base + slots, torch.zeros(len(ids), dtype=env.s.dtype, device=env.device))
        self.changed[ids] = True
        return len(ids)

    def _branches(self, ids: Tensor, seg: Tensor) -> tuple[Tensor, Tensor]:
        """Branch knots (B, K + 2, M) and counts (B,) of envs `ids` on paths `seg`, offsets drawn from the env's
        generator."""
        env, cfg, g = self.env, self.cfg, self.env.generator
        b, m = len(ids), env.paths.dof
        direction = torch.randn(b, m, generator=g, device=env.device, dtype=torch.float64)
        variant = torch.randint(len(cfg.offsets), (b,), generator=g, device=env.device)
        size = torch.as_tensor(cfg.offsets, dtype=torch.float64, device=env.device)[variant]
        ramp = torch.as_tensor(cfg.ramps, dtype=torch.float64, device=env.device)[variant]
        offset = size.unsqueeze(1) * direction / direction.norm(dim=1, keepdim=True).clamp(min=1e-12)
        p = env.paths
        k = p.knots.shape[1] - 2  # room left for the two start knots
        start = BranchStart(env.s[ids], env.pos[ids][:, env.path_index], env.vel[ids][:, env.path_index])
        shape = BranchShape(offset, ramp, self.pos_limits, cfg.lead_s, cfg.margin)
        end = env.end_knot[ids].clamp(max=k - 1)
        knots, count = branch_knots(p.knots[seg, :k], p.knot_s[seg, :k], end, start, shape)
        return dedupe_padded(knots, count)


def with_path_changes(cfg: dict[str, Any], env: Any) -> Any:
    """The training env of a run config: wrapped in :class:`PathChanges` when ``path_change.enabled``, else `env`
    itself (unchanged)."""
    pc = PathChangeCfg.from_run(cfg)
    return env if pc is None else PathChanges(env, pc)
