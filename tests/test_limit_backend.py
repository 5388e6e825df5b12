"""One explicit limit backend (issue 23, ``pathrl.limits.backend``): each env runs its own ``limit_backend``, a
``with backend.active():`` block scopes the rest, the process default is native-where-available and eager, run
configs choose it with ``native_limits`` / ``compile_limits`` (old saved runs back-filled), bad values are refused."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch
import yaml
from test_env import make_env

from pathrl import native
from pathrl.config.migrate import ADDED_KEYS, migrate
from pathrl.envs.tracking_cfg import TrackingEnvCfg
from pathrl.envs.trueadapt import AdaptEnvCfg
from pathrl.limits import kernels
from pathrl.limits.backend import DEFAULT, LimitBackend, current
from pathrl.train.runner import RESUME_MAY_CHANGE, config_change

ROOT = Path(__file__).resolve().parents[1]
NATIVE, TORCH = LimitBackend(native=True), LimitBackend(native=False)


def _actions(steps: int, n: int, d: int) -> list[torch.Tensor]:
    g = torch.Generator().manual_seed(7)
    return [torch.rand(n, d, generator=g) * 2.0 - 1.0 for _ in range(steps)]


def _state(env) -> list[torch.Tensor]:
    return [env.pos.clone(), env.vel.clone(), env.acc.clone(), env.a_min.clone(), env.a_max.clone(), env.s.clone()]


def _rollout(env, actions: list[torch.Tensor]) -> list[list[torch.Tensor]]:
    return [_state(env)] + [(env.step(a), _state(env))[1] for a in actions]


@pytest.fixture
def native_calls(monkeypatch) -> list[str]:
    """Names of the native functions called (valid_range, advance), in order."""
    calls: list[str] = []
    for name in ("valid_range", "advance"):
        fn = getattr(native, name)
        monkeypatch.setattr(native, name, lambda *a, _fn=fn, _name=name: (calls.append(_name), _fn(*a))[1])
    return calls


def test_defaults_are_native_where_available_and_eager():
    assert DEFAULT == LimitBackend() == LimitBackend(native=True, compiled=False) == current()
    assert TrackingEnvCfg().limit_backend is None and AdaptEnvCfg().limit_backend is None  # follow the scope
    env, _ = make_env(num_envs=2)
    assert env.limit_backend is None


def test_two_envs_in_one_process_run_their_own_backends(native_calls):
    """Interleaved steps of a native and a torch env, inside a block of the opposite backend each time: each equals
    a lone env run in its backend's block bit for bit, and only the native one calls the native code."""
    assert native.available()
    steps, n = 25, 16
    a_native, _ = make_env(num_envs=n, limit_backend=NATIVE)
    a_torch, _ = make_env(num_envs=n, limit_backend=TORCH)
    actions = _actions(steps, n, a_native.num_actions)
    got = {"native": [_state(a_native)], "torch": [_state(a_torch)]}
    for act in actions:
        native_calls.clear()
        with TORCH.active():
            a_native.step(act)
        assert native_calls == ["advance", "valid_range"]
        with NATIVE.active():
            a_torch.step(act)
        assert native_calls == ["advance", "valid_range"]  # none added by the torch env
        got["native"].append(_state(a_native))
        got["torch"].append(_state(a_torch))
    for name, backend in (("native", NATIVE), ("torch", TORCH)):
        with backend.active():
            alone, _ = make_env(num_envs=n)  # limit_backend None: follows the block
            ref = _rollout(alone, actions)
        for step_got, step_ref in zip(got[name], ref, strict=True):
            assert all(torch.equal(x, y) for x, y in zip(step_got, step_ref, strict=True)), name
    for s_native, s_torch in zip(got["native"], got["torch"], strict=True):  # and the two backends agree
        for x, y in zip(s_native, s_torch, strict=True):
            torch.testing.assert_close(x, y, rtol=0.0, atol=1e-12)


def test_compiled_setting_is_per_env(monkeypatch):
    """An env with ``compiled`` runs its kernels through torch.compile, its neighbour eagerly (torch.compile is
    replaced by a counting pass-through: no real compilation in this test)."""
    compiled_calls: list[str] = []

    def fake_compile(fn, dynamic=None):
        return lambda *a: (compiled_calls.append(fn.__name__), fn(*a))[1]

    monkeypatch.setattr(torch, "compile", fake_compile)
    monkeypatch.setattr(kernels, "_compiled", {})
    eager_env, _ = make_env(num_envs=8, limit_backend=TORCH)
    act = _actions(1, 8, eager_env.num_actions)[0]
    eager_env.step(act)
    assert compiled_calls == []
    compiled_env, _ = make_env(num_envs=8, limit_backend=LimitBackend(native=False, compiled=True))
    compiled_calls.clear()
    compiled_env.step(act)
    assert {"advance", "observe_state", "end_of_step"} <= set(compiled_calls)
    compiled_calls.clear()
    eager_env.step(act)
    assert compiled_calls == []


def test_active_blocks_nest_and_restore():
    assert current() == DEFAULT
    with TORCH.active() as outer:
        assert current() is outer is TORCH
        with LimitBackend(compiled=True).active():
            assert current() == LimitBackend(native=True, compiled=True)
        assert current() is TORCH
    assert current() == DEFAULT


@pytest.mark.parametrize("make,match", [
    (lambda: LimitBackend(native="yes"), r"^LimitBackend\.native must be true or false, got 'yes'$"),
    (lambda: LimitBackend(compiled=1), r"^LimitBackend\.compiled must be true or false, got 1$"),
    (lambda: LimitBackend.from_run({"native_limits": "no"}), r"^native_limits must be true or false, got 'no'$"),
    (lambda: LimitBackend.from_run({"compile_limits": None}), r"^compile_limits must be true or false, got None$"),
    (lambda: TrackingEnvCfg(limit_backend="native"), r"^env limit_backend must be a LimitBackend or None, got"),
    (lambda: AdaptEnvCfg(limit_backend=True), r"^env limit_backend must be a LimitBackend or None, got True$"),
])
def test_bad_values_give_a_one_line_error(make, match):
    with pytest.raises(ValueError, match=match) as err:
        make()
    assert "\n" not in str(err.value)


def test_run_config_chooses_the_backend_and_old_runs_keep_theirs():
    from pathrl.cli.common import compose, to_container
    from pathrl.schema import TrainAppCfg

    cfg = to_container(compose("train", [], TrainAppCfg))
    assert LimitBackend.from_run(cfg) == LimitBackend(native=True, compiled=True)  # pathrl-train's defaults
    cfg = to_container(compose("train", ["native_limits=false", "compile_limits=false"], TrainAppCfg))
    assert LimitBackend.from_run(cfg) == LimitBackend(native=False, compiled=False)
    assert ADDED_KEYS["native_limits"] is True and "native_limits" in RESUME_MAY_CHANGE
    for path in sorted((ROOT / "models").glob("*/*/config.yaml")):
        saved = yaml.safe_load(path.read_text())
        if "controller" in saved or "compile_limits" not in saved:
            continue
        native = saved.get("native_limits", True)  # saved before the key: native where available, as then
        backend = LimitBackend.from_run(migrate(saved))
        assert backend == LimitBackend(native=native, compiled=bool(saved["compile_limits"])), path.parent.name
        assert config_change(saved, {**migrate(saved), "native_limits": False}) == ""  # a resume may change it


def test_env_cfg_carries_the_backend_through_replace_and_describe():
    cfg = dataclasses.replace(TrackingEnvCfg(num_envs=2), limit_backend=TORCH)
    assert TrackingEnvCfg.from_mapping({"num_envs": 2}, limit_backend=TORCH) == cfg
    env, _ = make_env(num_envs=2, limit_backend=TORCH)
    assert env.limit_backend is TORCH
    assert env.describe()["cfg"]["limit_backend"] == {"native": False, "compiled": False}
