"""TD3 learner of the waypoint-adjustment policy (paper Sec. IV-C/D) and the learned IWA.

TD3 comes from torchrl (``TD3Loss``: twin critics, target policy smoothing, clipped double Q, importance
weights from the ``priority_weight`` key; ``SoftUpdate`` for the target networks); the networks are torchrl
``MLP`` s with tanh activations (the paper's choice against outliers) and a tanh output. Prioritized replay is
:class:`pathrl.industrial.per.PrioritizedBuffer` (torchrl's needs its C++ extension, which does not load with
torch 2.13). The policy maps one waypoint's 313 features to its 3 actions; all waypoints of a profile are
one batch. ``critic_action_gain`` scales the critic's action input: with 313 features of magnitude 1-10
against 3 actions in [-1, 1] the default-initialised critic is linear in the action (measured on the calibrated
model, docs/industrial.md), so it cannot represent an optimum inside the clip. Ablations zero feature groups
(``ablate``: ``p_target``, ``q_fjac``, ``e``) and turn PER off (``per_alpha = 0``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from pathrl.industrial.features import N_FEATURES, SLICES
from pathrl.industrial.iwa_env import IWAEpisode
from pathrl.industrial.metrics import POS_SPEC_MM
from pathrl.industrial.mpgd import IWAResult

__all__ = ["N_ACTIONS", "RLParams", "TD3Agent", "feature_mask", "run_policy_iwa"]

N_ACTIONS = 3
ABLATIONS = {"p_target": ("p_target",), "q_fjac": ("q", "f_jac"), "e": ("e",)}


@dataclass(frozen=True)
class RLParams:
    """TD3 + PER settings (training budget in IWA iterations, i.e. executions; the paper trains 5000)."""

    iterations: int = 3000
    k_max: int = 10
    hidden: list[int] = field(default_factory=lambda: [128, 128])
    lr_actor: float = 3e-4
    lr_critic: float = 3e-4
    gamma: float = 0.9
    tau: float = 0.005
    batch: int = 256
    updates_per_iter: int = 2
    policy_delay: int = 2
    expl_noise: float = 0.2
    expl_smooth: float = 0.0  # waypoints: Gaussian width of the exploration noise's correlation along the path
    policy_noise: float = 0.2
    critic_action_gain: float = 1.0  # the critic's action input x this (1 = plain concatenation; module doc)
    noise_clip: float = 0.5
    warmup: int = 30
    buffer: int = 60000
    per_alpha: float = 0.6
    per_beta: float = 0.4
    n_train: int = 300
    action_clip: float = 1.0  # the network's tanh output times this is the action (the paper: 2)
    w_ori: float = 1.0  # reward weight of the orientation improvement (the paper: 0.5)
    success_decay: float = 1.0  # success reward x success_decay^k at iteration k (the paper: 0.8)
    ablate: list[str] = field(default_factory=list)
    checkpoint_every: int = 500
    log_every: int = 20
    seed: int = 0

    def __post_init__(self) -> None:
        bad = [a for a in self.ablate if a not in ABLATIONS]
        if bad:
            raise ValueError(f"rl.ablate: unknown {bad[0]!r}; known: {', '.join(ABLATIONS)}")
        if not (0.0 < self.action_clip <= 2.0 and self.w_ori >= 0.0 and 0.0 < self.success_decay <= 1.0):
            raise ValueError("rl: need 0 < action_clip <= 2, w_ori >= 0, 0 < success_decay <= 1")
        if self.expl_smooth < 0.0 or self.expl_noise < 0.0 or self.critic_action_gain <= 0.0:
            raise ValueError("rl: need expl_noise >= 0, expl_smooth >= 0 (waypoints), critic_action_gain > 0")
        if self.iterations < 1 or self.k_max < 1 or self.batch < 1 or self.n_train < 1 or not self.hidden:
            raise ValueError("rl: iterations, k_max, batch, n_train must be >= 1 and hidden non-empty")


def feature_mask(ablate: list[str]) -> torch.Tensor:
    """(313,) mask that zeroes the ablated feature groups."""
    mask = torch.ones(N_FEATURES)
    for name in ablate:
        for group in ABLATIONS[name]:
            mask[SLICES[group]] = 0.0
    return mask


class TD3Agent:
    """torchrl TD3 (module doc) with its optimizers; ``act`` is numpy in, numpy out."""

    def __init__(self, params: RLParams) -> None:
        from tensordict import TensorDict
        from tensordict.nn import TensorDictModule
        from torchrl.data import Bounded
        from torchrl.modules import MLP, ValueOperator
        from torchrl.objectives import SoftUpdate, TD3Loss

        torch.manual_seed(params.seed)
        self.params, self.mask = params, feature_mask(params.ablate)
        actor_net = nn.Sequential(MLP(in_features=N_FEATURES, out_features=N_ACTIONS, num_cells=params.hidden,
                                      activation_class=nn.Tanh), nn.Tanh())
        self.actor = TensorDictModule(actor_net, in_keys=["observation"], out_keys=["action"])
        qvalue = ValueOperator(_Critic(params.hidden, params.critic_action_gain), in_keys=["observation", "action"])
        td0 = TensorDict({"observation": torch.zeros(2, N_FEATURES)}, [2])
        qvalue(self.actor(td0))
        self.loss = TD3Loss(self.actor, qvalue, action_spec=Bounded(-1.0, 1.0, shape=(N_ACTIONS,)),
                            num_qvalue_nets=2, policy_noise=params.policy_noise, noise_clip=params.noise_clip,
                            loss_function="l2", delay_actor=True, delay_qvalue=True)
        self.loss.make_value_estimator(gamma=params.gamma)
        self.target = SoftUpdate(self.loss, tau=params.tau)
        self.opt_q = torch.optim.Adam(self.loss.qvalue_network_params.values(True, True), params.lr_critic)
        self.opt_a = torch.optim.Adam(self.loss.actor_network_params.values(True, True), params.lr_actor)
        self.updates = 0

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic actions (m, 3) of features (m, 313)."""
        from tensordict import TensorDict

        x = torch.as_tensor(obs, dtype=torch.float32) * self.mask
        with torch.no_grad(), self.loss.actor_network_params.to_module(self.loss.actor_network):
            out = self.loss.actor_network(TensorDict({"observation": x}, [x.shape[0]]))
        return out["action"].double().numpy()

    def update(self, buffer) -> dict[str, float]:
        """One TD3 step on a prioritized batch (critic every step, actor and targets every policy_delay)."""
        batch = buffer.sample(self.params.batch)
        batch["observation"] = batch["observation"] * self.mask
        batch["next", "observation"] = batch["next", "observation"] * self.mask
        loss_q, meta = self.loss.value_loss(batch)
        self.opt_q.zero_grad()
        loss_q.backward()
        self.opt_q.step()
        out = {"loss_q": float(loss_q.detach())}
        if self.updates % self.params.policy_delay == 0:
            loss_a, _ = self.loss.actor_loss(batch)
            self.opt_a.zero_grad()
            loss_a.backward()
            self.opt_a.step()
            self.target.step()
            out["loss_actor"] = float(loss_a.detach())
        buffer.update_priority(batch["index"], meta["td_error"].max(0)[0].sqrt())
        self.updates += 1
        return out

    def state_dict(self) -> dict:
        """Networks, both optimizers and the update count (for a checkpoint)."""
        return {"loss": self.loss.state_dict(), "opt_q": self.opt_q.state_dict(), "opt_a": self.opt_a.state_dict(),
                "updates": self.updates}

    def load_state_dict(self, state: dict) -> None:
        """Restore what :meth:`state_dict` saved."""
        self.loss.load_state_dict(state["loss"])
        self.opt_q.load_state_dict(state["opt_q"])
        self.opt_a.load_state_dict(state["opt_a"])
        self.updates = int(state["updates"])


class _Critic(nn.Module):
    """Q(s, a): a tanh MLP of the features and `action_gain` x the action (module doc)."""

    def __init__(self, hidden: list[int], action_gain: float = 1.0) -> None:
        from torchrl.modules import MLP

        super().__init__()
        self.action_gain = float(action_gain)
        self.net = MLP(in_features=N_FEATURES + N_ACTIONS, out_features=1, num_cells=hidden,
                       activation_class=nn.Tanh)

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, self.action_gain * act], -1))


def run_policy_iwa(env: IWAEpisode, policy) -> IWAResult:
    """IWA with a policy (features (m, 313) -> actions (m, 3)) for up to env.k_max iterations; stops at the
    0.5 mm spec or a global termination. Returns the best program like :func:`pathrl.industrial.mpgd.run_mpgd`."""
    t0 = time.perf_counter()
    obs = env.reset()
    history = [env.errors.max_pos_mm]
    itr = 0 if history[0] <= POS_SPEC_MM else None
    while itr is None and env.k < env.k_max:
        res = env.step(policy(obs))
        if res.errors is None:
            break
        obs = res.obs
        history.append(res.errors.max_pos_mm)
        if res.errors.max_pos_mm <= POS_SPEC_MM:
            itr = env.k
        if res.terminal:
            break
    _, program, errors = env.best
    return IWAResult(program, errors, history, itr, len(history), time.perf_counter() - t0)
