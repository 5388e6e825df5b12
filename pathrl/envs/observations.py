"""Observation terms of the path-tracking env (:class:`~pathrl.envs.tracking.PathTrackingEnv`).

The env's observation is the concatenation of its active terms in the fixed order of :data:`OBS_TERMS`, clipped to
[-1, 1] and cast to float32 (:func:`assemble`). Shipped policies depend on this order and on each term's columns:
never reorder the terms; a new term goes last (a warm start then appends its inputs).

Terms (each: a pure function of env-state tensors -> (N, k) float64 before clipping, and its size k):
  state     always: commanded joint position / velocity / acceleration (normalized), the knot window, the position
            inside the knot interval, the window's length, the distance of each window knot; with ``end_obs`` the
            vector to the end knot and the arc length left (:func:`observe_state`; columns: :func:`state_fields`)
  feedback  with a feedback source and ``feedback_obs``: the task's sensor values (``feedback.observe()``, e.g. the
            ball's previous and current position on the plate, + the plate IMU)
  tcp       with ``tcp_obs``: per TCP the reference TCP position at s in ``tcp_obs_box`` -> [-1, 1], then reference
            minus commanded TCP / ``tcp_obs_error`` (:func:`tcp_observation`)
  error     with ``error_obs``: per path joint the reference at s minus the commanded position / ``error_obs_scale``
            (:func:`path_error`)

:func:`observation_layout` (``env.observation_layout()``, also in ``env.describe()["obs_layout"]``) names the
columns: (term, start, stop) slices that cover the observation exactly.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
from torch import Tensor

from pathrl.limits.kernels import kernel

if TYPE_CHECKING:
    from pathrl.envs.tracking import PathTrackingEnv

__all__ = ["OBS_ORDER", "OBS_TERMS", "ObsTerm", "active_terms", "assemble", "column_slices", "critic_observation",
           "feedback_size", "observation_layout", "observe_state", "path_error", "reference_and_commanded_tcp",
           "state_fields", "state_size", "tcp_distance", "tcp_observation", "tcp_size", "tracking_state"]


@kernel(static=True)
def observe_state(pos: Tensor, vel: Tensor, acc: Tensor, pos_lim: Tensor, vel_lim: Tensor, acc_lim: Tensor,
                  path_index: Tensor, knots: Tensor, knot_s: Tensor, path: Tensor, knot_i: Tensor, s: Tensor,
                  end_knot: Tensor, end_q: Tensor, end_s: Tensor, n_state: int, horizon: float, knot_gap: float,
                  relative: bool, end_obs: bool) -> tuple[Tensor, Tensor, Tensor]:
    """The tracking state of N envs (the layout of the module docstring, before clipping), float64 (N, k).

    pos, vel, acc: (N, D); pos_lim (D, 2), vel_lim, acc_lim (D,); knots (P, K, M) / knot_s (P, K) of the
    path bank, padded; path, knot_i (last knot at or behind s), end_knot: (N,) long; s, end_s: (N,) arc
    length; end_q: (N, M) end knot. Also returns l_obs (N,): arc length of the window's last knot, and
    close_to_end (N,): the window reaches the end knot.
    """
    lo, hi = pos_lim[:, 0], pos_lim[:, 1]
    pos_n = 2.0 * (pos - lo) / (hi - lo) - 1.0
    i0 = torch.minimum(knot_i, end_knot)
    ii = torch.minimum(i0.unsqueeze(1) + torch.arange(n_state, device=s.device), end_knot.unsqueeze(1))  # (N, n)
    win = knots[path.unsqueeze(1), ii]  # (N, n, M)
    ks = knot_s[path.unsqueeze(1), ii]
    q = pos.index_select(1, path_index)
    if relative:  # translation invariant: the direction and distance to each knot
        knots_n = ((win - q.unsqueeze(1)) / horizon).flatten(1)
    else:
        plo, phi = lo.index_select(0, path_index), hi.index_select(0, path_index)
        knots_n = (2.0 * (win - plo) / (phi - plo) - 1.0).flatten(1)
    d0 = ks[:, :1]
    inside = 2.0 * (s.unsqueeze(1) - d0) / knot_gap - 1.0
    ahead = 2.0 * (ks - d0) / horizon - 1.0  # [:, -1] is the window length
    parts = [pos_n, vel / vel_lim, acc / acc_lim, knots_n, inside, ahead[:, -1:], ahead[:, 1:]]
    if end_obs:
        to_end = (end_q - q) / knot_gap
        left = 2.0 * ((end_s - s) / knot_gap).clamp(0.0, 1.0) - 1.0
        parts += [to_end, left.unsqueeze(1)]
    return torch.cat(parts, dim=1), ks[:, -1], ks[:, -1] >= end_s


def state_fields(dof: int, path_dof: int, n_state: int, end_obs: bool) -> list[tuple[str, int]]:
    """The columns of :func:`observe_state` in order, as (field, size): pos, vel, acc (D each), knots (n_state M,
    knot by knot), inside, window (the window's length), ahead (n_state - 1), with end_obs to_end (M), left."""
    fields = [("pos", dof), ("vel", dof), ("acc", dof), ("knots", n_state * path_dof), ("inside", 1),
              ("window", 1), ("ahead", n_state - 1)]
    return fields + ([("to_end", path_dof), ("left", 1)] if end_obs else [])


def state_size(dof: int, path_dof: int, n_state: int, end_obs: bool) -> int:
    """Columns of the state term: 3 D + n_state M + n_state + 1 (+ M + 1 with end_obs)."""
    return sum(size for _, size in state_fields(dof, path_dof, n_state, end_obs))


def tcp_observation(ref: Tensor, cmd: Tensor, box: Tensor, error_scale: float) -> Tensor:
    """The TCP part of the state, before clipping: reference and commanded TCP positions (N, T, 3) in metres,
    `box` (3, 2) [min, max] per axis -> (N, 6 T): per TCP the reference mapped from the box to [-1, 1], then
    (reference - commanded) / error_scale."""
    ref_n = 2.0 * (ref - box[:, 0]) / (box[:, 1] - box[:, 0]) - 1.0
    return torch.cat([ref_n, (ref - cmd) / error_scale], dim=2).flatten(1)


def tcp_size(num_tcps: int) -> int:
    """Columns of the tcp term: 6 per TCP (reference position, reference - commanded)."""
    return 6 * num_tcps


# ---------------------------------------------------------------------------------------- the env's terms
def tracking_state(env: PathTrackingEnv) -> tuple[Tensor, Tensor, Tensor]:
    """:func:`observe_state` of the env's current state: the state term (N, k), l_obs and close_to_end (N,)."""
    lim, cfg = env.limits, env.cfg
    return observe_state(env.pos, env.vel, env.acc, lim.pos, lim.vel, lim.acc, env.path_index, env.paths.knots,
                         env.paths.knot_s, env.seg_path, env.knot_i, env.s, env.end_knot, env.end_q, env.end_s,
                         cfg.n_state, env.horizon, env.knot_gap, cfg.knot_obs == "relative", cfg.end_obs)


def _state(env: PathTrackingEnv) -> Tensor:
    return tracking_state(env)[0]


def _state_size(env: PathTrackingEnv) -> int:
    return state_size(env.robot.dof, len(env.path_index), env.cfg.n_state, env.cfg.end_obs)


def _feedback(env: PathTrackingEnv) -> Tensor:
    return env.feedback.observe().to(torch.float64)


def feedback_size(env: PathTrackingEnv) -> int:
    """Columns of the feedback term: the feedback source's ``num_obs``."""
    return int(env.feedback.num_obs)


def reference_and_commanded_tcp(env: PathTrackingEnv, pos: Tensor, s: Tensor) -> tuple[Tensor, Tensor]:
    """TCP positions (N, T, 3) in metres of the reference at arc length `s` (N,) (joints outside the path as
    commanded) and of the commanded configuration `pos` (N, D), in one forward-kinematics call."""
    ref = pos.clone()
    ref[:, env.path_index] = env.paths.position_at(env.seg_path, s)
    tcp = env.fk.tcp_positions(torch.cat([ref, pos]))
    return tcp[:env.num_envs], tcp[env.num_envs:]


def tcp_distance(env: PathTrackingEnv, pos: Tensor, s: Tensor) -> Tensor:
    """Mean distance (N,) in metres of the commanded TCPs at `pos` (N, D) from the reference TCPs at `s` (N,)."""
    ref, cmd = reference_and_commanded_tcp(env, pos, s)
    return (ref - cmd).norm(dim=2).mean(dim=1)


def _tcp(env: PathTrackingEnv) -> Tensor:
    """The tcp term at the env's current state (reference at s)."""
    ref, cmd = reference_and_commanded_tcp(env, env.pos, env.s)
    return tcp_observation(ref, cmd, env.tcp_box, env.cfg.tcp_obs_error)


def _tcp_size(env: PathTrackingEnv) -> int:
    return tcp_size(len(env.robot.tcps))


def path_error(env: PathTrackingEnv) -> Tensor:
    """The error term (N, M): per path joint the reference at the path position s minus the commanded position,
    / ``error_obs_scale`` (rad). The knot window shows where the path goes; this shows how far off it the robot is
    now, which the window gives only through the spline between its knots."""
    ref = env.paths.position_at(env.seg_path, env.s)
    return (ref - env.pos.index_select(1, env.path_index)) / env.cfg.error_obs_scale


@dataclass(frozen=True)
class ObsTerm:
    """One observation term: whether an env has it, its columns, and its values (N, size) before clipping."""

    name: str
    active: Callable[[PathTrackingEnv], bool]
    size: Callable[[PathTrackingEnv], int]
    observe: Callable[[PathTrackingEnv], Tensor]
    summary: str


#: The observation terms in their fixed order (the observation's column order; never reorder).
OBS_TERMS: dict[str, ObsTerm] = {t.name: t for t in (
    ObsTerm("state", lambda env: True, _state_size, _state, "robot state and knot window (+ end knot)"),
    ObsTerm("feedback", lambda env: env.feedback is not None and env.cfg.feedback_obs, feedback_size, _feedback,
            "the task's sensor values (env.feedback_obs)"),
    ObsTerm("tcp", lambda env: bool(env.cfg.tcp_obs), _tcp_size, _tcp,
            "reference TCP and reference - commanded TCP (env.tcp_obs)"),
    ObsTerm("error", lambda env: bool(env.cfg.error_obs), lambda env: len(env.path_index), path_error,
            "reference at s - commanded position per path joint (env.error_obs)"),
)}
#: Their names in order.
OBS_ORDER = tuple(OBS_TERMS)


def critic_observation(env: PathTrackingEnv) -> Tensor:
    """The privileged group of an asymmetric critic (``task.critic_obs``) (N, 2 + k) float32: the time left before
    the episode's time limit (s) / 10, the arc length left to the segment's end (rad) / 10, and the feedback
    source's ``privileged()`` values (k of them; none for a source without it, e.g. the PyBullet ball, which only
    evaluations use: they load the actor alone)."""
    left = (env.budget - env.episode_length_buf).to(torch.float64) * env.cfg.dt / 10.0
    parts = [left[:, None], ((env.end_s - env.s) / 10.0)[:, None]]
    privileged = getattr(env.feedback, "privileged", None)
    if privileged is not None:
        parts.append(privileged().to(env.device))
    return torch.cat(parts, dim=1).to(torch.float32)


def active_terms(env: PathTrackingEnv) -> list[ObsTerm]:
    """The env's observation terms, in the order of :data:`OBS_TERMS`."""
    return [t for t in OBS_TERMS.values() if t.active(env)]


def assemble(terms: Sequence[ObsTerm], env: PathTrackingEnv, known: Mapping[str, Tensor] | None = None) -> Tensor:
    """The observation (N, sum of sizes) float32: the terms' values concatenated in order, clipped to [-1, 1].
    `known`: values of terms already computed (the env's state term, computed with the window's end)."""
    known = known or {}
    parts = [known[t.name] if t.name in known else t.observe(env) for t in terms]
    return torch.cat(parts, dim=1).clamp(-1.0, 1.0).to(torch.float32)


def observation_layout(terms: Sequence[ObsTerm], env: PathTrackingEnv,
                       fields: bool = False) -> list[tuple[str, int, int]]:
    """(name, start, stop) column slices of the observation, in order; they cover it exactly. With `fields` the
    state term is split into its fields (``state/pos``, ... :func:`state_fields`)."""
    sizes = []
    for t in terms:
        if fields and t.name == "state":
            sizes += [(f"state/{f}", k) for f, k in state_fields(env.robot.dof, len(env.path_index),
                                                                 env.cfg.n_state, env.cfg.end_obs)]
        else:
            sizes.append((t.name, t.size(env)))
    return column_slices(sizes)


def column_slices(sizes: Sequence[tuple[str, int]]) -> list[tuple[str, int, int]]:
    """(name, size) parts laid side by side -> (name, start, stop) column slices, in order."""
    out, start = [], 0
    for name, k in sizes:
        out.append((name, start, start + k))
        start += k
    return out
