"""Training curricula that depend only on the iteration (so a resumed run continues them where it stopped).

* the ball (``task.curriculum``, :class:`pathrl.schema.BallCurriculumCfg`): new balls roll less and start nearer
  the plate's centre at first, moving to the task's own balls;
* reward term weights (``reward_curriculum``, :class:`pathrl.schema.RewardCurriculumCfg`): the terms start at
  another weight and move linearly to the reward's configured ones, e.g. the path-length weight of the ball task
  low at first (keep the ball, then get fast), or its deviation weights high (get close to the path, then fast),
  the configured reward from the given iteration on.

Each is applied to the training env before every rollout through a runner hook
(:meth:`pathrl.train.runner.PathRLRunner.after_each_update`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from pathrl.envs.state import unwrapped
from pathrl.schema import BallCurriculumCfg, RewardCurriculumCfg

__all__ = ["apply_ball_curriculum", "apply_reward_curriculum", "curriculum_scales", "reward_weight"]


def _progress(it: int, iterations: int) -> float:
    """How far iteration `it` is through a curriculum of `iterations`, clamped to [0, 1]."""
    return min(max(it / max(iterations, 1), 0.0), 1.0)


def curriculum_scales(it: int, cur: BallCurriculumCfg) -> tuple[float, float]:
    """(rolling-friction scale, start spread) of new balls at iteration `it` of the ball curriculum: the friction
    scale log-linear from ``cur.friction_scale`` to 1, the spread linear from ``cur.start_spread`` to 1, both reached
    at ``cur.iterations``."""
    frac = _progress(it, cur.iterations)
    return cur.friction_scale ** (1.0 - frac), cur.start_spread + (1.0 - cur.start_spread) * frac


def reward_weight(it: int, cur: RewardCurriculumCfg, final: float) -> float:
    """The weight of the curriculum's term at iteration `it`: linear from ``cur.initial`` to `final` (the reward's
    configured weight), reached at ``cur.iterations``."""
    return cur.initial + (final - cur.initial) * _progress(it, cur.iterations)


def apply_ball_curriculum(runner: Any, cur: BallCurriculumCfg) -> None:
    """Set the training env's ball curriculum before every rollout (ValueError: no analytic ball to set it on)."""
    ball = getattr(unwrapped(runner.env), "feedback", None)
    ball = getattr(ball, "inner", ball)  # open loop: the ball behind the frozen sensor
    if not hasattr(ball, "set_curriculum"):
        raise ValueError("task.curriculum needs the analytic ball in training (task.feedback ball_on_plate, "
                         "task.backend analytic)")

    def apply(it: int) -> None:
        ball.set_curriculum(*curriculum_scales(it, cur))

    apply(runner.current_learning_iteration)
    runner.after_each_update(apply)


def apply_reward_curriculum(runner: Any, cur: RewardCurriculumCfg) -> None:
    """Set the weights of the curriculum's reward terms of the training env before every rollout (ValueError, one
    line: the env's reward has no such term)."""
    env = unwrapped(runner.env)
    terms = list(getattr(env, "reward_terms", []))
    names = [t.name for t in terms]
    moved = [cur.term, *cur.also]
    for name in moved:
        if name not in names:
            raise ValueError(f"reward_curriculum: the reward has no term {name!r}; it has {', '.join(names) or 'none'}")
    finals = {i: t.weight for i, t in enumerate(terms) if t.name in moved}

    def apply(it: int) -> None:
        for i, final in finals.items():
            env.reward_terms[i] = dataclasses.replace(env.reward_terms[i], weight=reward_weight(it, cur, final))

    apply(runner.current_learning_iteration)
    runner.after_each_update(apply)
