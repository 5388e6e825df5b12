"""`reproduce_tables.py --reuse` keeps a result only while its inputs are unchanged (pathrl.repro.inputs; the steps:
pathrl.repro.steps)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import pytest

from pathrl.repro import steps
from pathrl.repro import trueadapt as adapt
from pathrl.repro.inputs import fingerprint, inputs_file, record, stale
from pathrl.repro.layout import PROFILES, Layout
from pathrl.repro.tables import Evaluation

ROOT = Path(__file__).resolve().parents[1]


def _model(root: Path, name: str, weights: bytes | None, policy: str | None = None) -> Path:
    """A fake models/<family>/<name>: config.yaml (naming `policy` under controller) and model.pt (None: a
    controller)."""
    d = root / "models" / "tracking" / name
    d.mkdir(parents=True, exist_ok=True)
    ctrl = "" if policy is None else f"controller:\n  name: balance\n  policy: {policy}\n"
    (d / "config.yaml").write_text(f"experiment: {name}\n{ctrl}")
    if weights is not None:
        (d / "model.pt").write_bytes(weights)
    return d


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """A fake repository: a controller naming models/tracking/policy_a, policies a and b, a test split."""
    _model(tmp_path, "policy_a", b"weights a")
    _model(tmp_path, "policy_b", b"weights b")
    _model(tmp_path, "balance", None, policy="models/tracking/policy_a")
    data = tmp_path / "datasets" / "armar4" / "target_point"
    data.mkdir(parents=True)
    (data / "dataset.json").write_text('{"seed": 0}')
    (data / "test.npz").write_bytes(b"paths")
    return tmp_path


def _split(root: Path) -> Path:
    return root / "datasets" / "armar4" / "target_point"


def test_fingerprint_follows_the_controller_policy(repo: Path):
    fp = fingerprint(repo, repo / "models" / "tracking" / "balance", _split(repo))
    assert sorted(fp) == ["datasets/armar4/target_point/dataset.json", "datasets/armar4/target_point/test.npz",
                          "models/tracking/balance/config.yaml", "models/tracking/policy_a/config.yaml",
                          "models/tracking/policy_a/model.pt"]
    relative = fingerprint(repo, Path("models/tracking/balance"), Path("datasets/armar4/target_point"))  # to root
    assert fp == relative
    assert all(len(h) == 64 for h in fp.values())


def test_changed_policy_or_weights_means_re_evaluate(repo: Path):
    result = repo / "results" / "raw" / "balance" / "metrics.json"
    result.parent.mkdir(parents=True)
    result.write_text("{}")
    inputs = fingerprint(repo, repo / "models" / "tracking" / "balance", _split(repo))
    record(result, inputs)
    assert json.loads((result.parent / "inputs.json").read_text())["files"] == inputs
    assert stale(result, fingerprint(repo, repo / "models" / "tracking" / "balance", _split(repo))) is None

    _model(repo, "balance", None, policy="models/tracking/policy_b")  # the controller now drives another policy
    why = stale(result, fingerprint(repo, repo / "models" / "tracking" / "balance", _split(repo)))
    assert why is not None and why.startswith("inputs changed") and "models/tracking/policy_b/model.pt" in why

    _model(repo, "balance", None, policy="models/tracking/policy_a")
    (repo / "models" / "tracking" / "policy_a" / "model.pt").write_bytes(b"retrained a")  # new weights, same policy
    why = stale(result, fingerprint(repo, repo / "models" / "tracking" / "balance", _split(repo)))
    assert why == "inputs changed (models/tracking/policy_a/model.pt)"


def test_missing_fingerprint_is_reusable_missing_result_is_not(repo: Path):
    inputs = fingerprint(repo, repo / "models" / "tracking" / "policy_a", _split(repo))
    result = repo / "results" / "raw" / "policy_a" / "metrics.json"
    assert stale(result, inputs) == "no result"
    result.parent.mkdir(parents=True)
    result.write_text("{}")
    assert stale(result, inputs) is None  # made before inputs were recorded (the committed results): kept
    inputs_file(result).write_text("not json")
    assert stale(result, inputs) == "inputs changed (inputs.json unreadable)"


def test_sidecar_of_a_file_result(tmp_path: Path):
    assert inputs_file(tmp_path / "path_change_iiwa7_random.json") == tmp_path / "path_change_iiwa7_random.inputs.json"
    assert inputs_file(tmp_path / "x" / "metrics.json") == tmp_path / "x" / "inputs.json"


def test_evaluate_reuses_until_the_policy_changes(repo: Path, monkeypatch, capsys):
    """The `evaluate` step on a fake layout (the evaluation command stubbed: nothing runs)."""
    runs: list[list[str]] = []

    def fake_sh(cmd: list[str], log: Path) -> None:
        runs.append(cmd)
        out = Path(next(a for a in cmd if a.startswith("out="))[4:])
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text("{}")

    monkeypatch.setattr(steps, "sh", fake_sh)
    monkeypatch.setattr(steps, "CONTROLLER_MODELS", frozenset({"balance"}))
    (repo / "models" / "tracking" / "balance" / "config.yaml").write_text(
        f"controller:\n  name: balance\n  policy: {repo / 'models' / 'tracking' / 'policy_a'}\n")
    lay = Layout(repo / "results", repo / "models", repo / "runs", repo / "datasets", repo / "data")
    e = Evaluation("balance", "armar4", "target_point")
    raw = repo / "results" / "raw" / e.id

    def run() -> None:
        steps.evaluate(e, PROFILES["quick"], lay, True, repo / "results" / "logs")

    raw.mkdir(parents=True)
    (raw / "metrics.json").write_text("{}")
    run()  # a result without inputs.json: kept, nothing recorded
    assert runs == [] and not (raw / "inputs.json").exists()
    (raw / "metrics.json").unlink()
    run()  # no result: evaluated, inputs recorded
    assert len(runs) == 1 and (raw / "inputs.json").is_file()
    run()  # unchanged: kept
    assert len(runs) == 1
    (repo / "models" / "tracking" / "balance" / "config.yaml").write_text(
        f"controller:\n  name: balance\n  policy: {repo / 'models' / 'tracking' / 'policy_b'}\n")
    run()  # the controller names another policy: re-evaluated, and said so
    assert len(runs) == 2
    assert "inputs changed" in capsys.readouterr().out
    run()
    assert len(runs) == 2


def test_a_batch_records_what_it_wrote_even_when_a_line_failed(tmp_path: Path, monkeypatch):
    """evaluate_batch: one pathrl-eval batch=FILE for the jobs to do (a kept one is left out); results written are
    recorded with their inputs, also when another line failed (StepFailed)."""
    calls: list[list[str]] = []

    def fake_sh(cmd: list[str], log: Path) -> None:
        calls.append(cmd)
        lines = Path(cmd[1].removeprefix("batch=")).read_text().splitlines()
        out = Path(shlex.split(lines[0])[-1].removeprefix("out="))
        out.mkdir(parents=True)
        (out / "metrics.json").write_text("{}")  # the first line ran, the second failed
        raise steps.StepFailed("exit 1: 1 of 2 evaluations failed")

    monkeypatch.setattr(steps, "sh", fake_sh)
    jobs = [steps.EvalJob([f"run_dir=m{i}", f"out={tmp_path / 'raw' / str(i)}"], tmp_path / "raw" / str(i) /
                          "metrics.json", {}) for i in range(2)]
    with pytest.raises(steps.StepFailed):
        steps.evaluate_batch("t", [lambda: None, lambda: jobs[0], lambda: jobs[1]], tmp_path / "logs")
    assert len(calls) == 1 and Path(calls[0][0]).name == "pathrl-eval"
    assert len((tmp_path / "logs" / "batch_t.txt").read_text().splitlines()) == 2
    assert (tmp_path / "raw" / "0" / "inputs.json").is_file() and not (tmp_path / "raw" / "1").exists()
    steps.evaluate_batch("none", [lambda: None], tmp_path / "logs")  # nothing to do: no process
    assert len(calls) == 1


def test_path_change_re_evaluates_new_weights(repo: Path, monkeypatch):
    runs: list[list[str]] = []

    def fake_sh(cmd: list[str], log: Path) -> None:
        runs.append(cmd)
        Path(cmd[5]).parent.mkdir(parents=True, exist_ok=True)
        Path(cmd[5]).write_text("{}")

    monkeypatch.setattr(steps, "sh", fake_sh)
    lay = Layout(repo / "results", repo / "models", repo / "runs", repo / "datasets", repo / "data")

    def run() -> None:
        steps.path_change("armar4/target_point", "policy_a", "armar4/target_point", PROFILES["quick"], lay, True,
                          repo / "results" / "logs")

    run()
    run()
    assert len(runs) == 1 and (repo / "results" / "raw" / "path_change_armar4_target_point.inputs.json").is_file()
    (repo / "models" / "tracking" / "policy_a" / "model.pt").write_bytes(b"retrained a")
    run()
    assert len(runs) == 2


def test_trueadapt_evaluation_records_its_inputs(tmp_path: Path, monkeypatch):
    """A TrueAdapt evaluation (the reference: the controller directory
    models/trueadapt/iiwa7_trueadapt_on_plate_reference) on the committed split runs pathrl-eval, no tool script:
    recorded, then kept."""
    runs: list[list[str]] = []

    def fake_sh(cmd: list[str], log: Path) -> None:  # pathrl-eval batch=FILE: the plan's TrueAdapt step
        cmd = [cmd[0], *shlex.split(Path(cmd[1].removeprefix("batch=")).read_text())]
        runs.append(cmd)
        out = Path(next(a for a in cmd if a.startswith("out="))[4:])
        out = out if out.is_absolute() else steps.ROOT / out
        assert out == tmp_path / "raw" / a.id
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text("{}")

    monkeypatch.setattr(steps, "sh", fake_sh)
    lay = Layout(tmp_path, tmp_path / "models", tmp_path / "runs", tmp_path / "datasets", tmp_path / "data")
    a = adapt.AdaptEval("on_plate")
    for _ in range(2):
        steps.evaluate_batch("t", [lambda: steps.adapt_job(a, PROFILES["quick"], lay, True)], tmp_path / "logs")
    files = json.loads((tmp_path / "raw" / a.id / "inputs.json").read_text())["files"]
    assert len(runs) == 1 and Path(runs[0][0]).name == "pathrl-eval" and not any("tools/" in x for x in runs[0])
    assert sorted(files) == ["datasets/iiwa7/trueadapt_on_plate/dataset.json",
                             "datasets/iiwa7/trueadapt_on_plate/test.npz",
                             "models/trueadapt/iiwa7_trueadapt_on_plate_reference/config.yaml"]


def test_train_jobs_train_a_generalization_row_on_its_train_dataset(monkeypatch):
    """--train: Table IV's rows train on their train_dataset (random_broad), not on the target point paths they are
    evaluated on; a generalization row without one and a second test split train nothing themselves."""
    from pathrl.repro.tables import ROWS, TABLE_IV, Evaluation

    evals = [r.evaluation for r in ROWS if r.table == TABLE_IV]
    jobs = steps.training_jobs(evals)
    assert jobs["iiwa7_random_broad_track_distill"].dataset == "random_broad"
    assert jobs["armar4_random_broad_track_distill"].dataset == "random_broad"
    assert not any(e.dataset == "target_point" for e in jobs.values())
    assert "iiwa7_random" not in jobs  # trained by its own rows (Tables I-III), not on target points
    plain = Evaluation("iiwa7_random", "iiwa7", "random")
    assert steps.training_jobs([plain, Evaluation("x", "iiwa7", "random", second_test_set=True)]) == \
        {"iiwa7_random": plain}
