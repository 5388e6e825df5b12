"""Proportional prioritized experience replay (Schaul et al., 2016) in torch, for the TD3 learner.

torchrl's ``PrioritizedReplayBuffer`` needs its C++ segment tree, whose extension does not load against torch
2.13 here (``SumSegmentTreeFp32 is not available``; see ``/work/shared/notes/libraries_wave2.md`` sec. 2), so
this small buffer stands in for it: a ring buffer of transitions, sampling with probability p_i^alpha / sum
(``torch.multinomial``, O(N) per draw: ~1 ms at 1e5 entries), importance weights (N P(i))^-beta / max, new
transitions at the current maximum priority, priorities updated to |td error| + eps. With ``alpha = 0`` it is
a uniform buffer (the paper's "RL - PER" ablation). Sampled batches are TensorDicts laid out as torchrl's losses
expect (observation, action, next/{observation, reward, done, terminated}, index, priority_weight).
"""

from __future__ import annotations

import torch
from tensordict import TensorDict

__all__ = ["PrioritizedBuffer"]


class PrioritizedBuffer:
    """Ring buffer of `capacity` transitions with `n_obs` features and `n_act` actions (module doc)."""

    def __init__(self, capacity: int, n_obs: int, n_act: int, alpha: float = 0.6, beta: float = 0.4,
                 eps: float = 1e-6, generator: torch.Generator | None = None) -> None:
        if capacity < 1 or alpha < 0 or not 0 <= beta <= 1:
            raise ValueError("buffer: need capacity >= 1, alpha >= 0, 0 <= beta <= 1")
        self.capacity, self.alpha, self.beta, self.eps = capacity, alpha, beta, eps
        self.obs = torch.zeros(capacity, n_obs)
        self.next_obs = torch.zeros(capacity, n_obs)
        self.action = torch.zeros(capacity, n_act)
        self.reward = torch.zeros(capacity, 1)
        self.done = torch.zeros(capacity, 1, dtype=torch.bool)
        self.priority = torch.zeros(capacity, dtype=torch.float64)
        self.size, self.cursor = 0, 0
        self.generator = generator if generator is not None else torch.Generator().manual_seed(0)

    def __len__(self) -> int:
        return self.size

    def add(self, obs: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, next_obs: torch.Tensor,
            done: torch.Tensor) -> None:
        """Append B transitions: obs (B, n_obs), action (B, n_act), reward (B,), next_obs, done (B,)."""
        n = obs.shape[0]
        idx = (self.cursor + torch.arange(n)) % self.capacity
        top = self.priority[: self.size].max().item() if self.size else 1.0
        self.obs[idx], self.action[idx], self.next_obs[idx] = obs.float(), action.float(), next_obs.float()
        self.reward[idx, 0], self.done[idx, 0] = reward.float(), done.bool()
        self.priority[idx] = top
        self.cursor = int((self.cursor + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch: int) -> TensorDict:
        """A batch of `batch` transitions drawn by priority, with their indices and importance weights."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty buffer")
        p = self.priority[: self.size] ** self.alpha
        p = p / p.sum()
        idx = torch.multinomial(p, batch, replacement=True, generator=self.generator)
        w = (self.size * p[idx]) ** (-self.beta)
        w = (w / w.max()).float()
        nxt = TensorDict({"observation": self.next_obs[idx], "reward": self.reward[idx], "done": self.done[idx],
                          "terminated": self.done[idx]}, [batch])
        return TensorDict({"observation": self.obs[idx], "action": self.action[idx], "next": nxt, "index": idx,
                           "priority_weight": w}, [batch])

    def update_priority(self, index: torch.Tensor, td_error: torch.Tensor) -> None:
        """Set the priorities of sampled transitions to |td_error| + eps."""
        self.priority[index] = td_error.detach().abs().double() + self.eps
