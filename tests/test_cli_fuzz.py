"""CLI fuzz, round three (issue 50): the table of tools/cli_fuzz.py over every entry point (train, eval, toppra,
dataset, export, view, industrial, the TrueAdapt tools): each bad input exits 2 with exactly one line on stderr, no
traceback, and nothing left behind. Then the pieces they rest on (output destinations, Hydra quoting, the agent
checks) and the results that used to be silently wrong (an evaluation written into models/)."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest
import yaml

from pathrl.models import model_dir

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import cli_fuzz  # noqa: E402  (tools/cli_fuzz.py: the case table and its runner)

sys.path.pop(0)


@pytest.fixture(scope="module")
def fuzz_dirs():
    with cli_fuzz.fuzz_dirs() as dirs:
        yield dirs


@pytest.mark.filterwarnings("ignore::DeprecationWarning")
@pytest.mark.parametrize("case", cli_fuzz.CASES, ids=lambda c: c.name)
def test_bad_input_is_one_line_and_leaves_nothing(case, fuzz_dirs):
    fix, work = fuzz_dirs
    o = cli_fuzz.run_case(case, fix, work)
    assert o.ok, (f"{case.program} {' '.join(case.args)}: exit {o.code}, {len(o.lines)} stderr lines "
                  f"{o.lines[-3:]}, traceback {o.traceback}, left behind {o.leftovers[:5]}, expected {o.expect!r}")


def test_every_entry_point_is_fuzzed():
    from test_docs import scripts

    fuzzed = {c.program for c in cli_fuzz.CASES}
    wanted = set(scripts()) | {
        "tools/trueadapt_eval.py", "tools/trueadapt_record.py", "tools/trueadapt_validation.py"}
    assert wanted <= fuzzed, sorted(wanted - fuzzed)


def _listing(root: Path) -> list[tuple[str, int, int]]:
    return sorted((str(p), p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*"))


def test_destination_checks_write_nothing(tmp_path):
    from pathrl.storage import DestinationError, check_dir_destination, check_file_destination, inside_models

    (tmp_path / "f").write_text("x")
    (tmp_path / "d").mkdir()
    before = _listing(tmp_path)
    assert check_file_destination(tmp_path / "new" / "deeper" / "x.json", "out") == tmp_path / "new/deeper/x.json"
    assert check_dir_destination(tmp_path / "d", "out", ("metrics.json",)) == tmp_path / "d"
    for call, msg in [(lambda: check_file_destination(tmp_path / "d", "out"), "is a directory"),
                      (lambda: check_file_destination(tmp_path / "f" / "x", "--save"), "--save"),
                      (lambda: check_dir_destination(tmp_path / "f", "out"), "is a file"),
                      (lambda: check_dir_destination(tmp_path / "f" / "sub", "out"), "is a file"),
                      (lambda: check_file_destination("", "out"), "not a file name")]:
        with pytest.raises(DestinationError, match=msg):
            call()
    assert _listing(tmp_path) == before
    assert inside_models(tmp_path / "models" / "a" / "b", roots=[tmp_path / "models"])
    assert not inside_models(tmp_path / "models_eval", roots=[tmp_path / "models"])
    assert inside_models(model_dir("iiwa7_random"))


def test_hydra_quoting_and_option_lists():
    from pathrl.cli.common import compose, hydra_safe

    assert hydra_safe(["dataset.path=/data/tëst run", "rows=[\"Typ ä\"]", "reward=a,b", "-m", "seed=1"]) == [
        "dataset.path='/data/tëst run'", "rows=[\"Typ ä\"]", "reward=a,b", "-m", "seed=1"]
    from pathrl.schema import ToppraAppCfg

    assert compose("toppra_app", ["dataset.path=/tmp/dätä"], ToppraAppCfg).dataset.path == "/tmp/dätä"


def test_every_shipped_and_default_agent_config_passes_the_checks():
    from pathrl.config.agent import check_agent

    configs = [yaml.safe_load(p.read_text()) for p in sorted((ROOT / "models").glob("*/*/config.yaml"))]
    agents = [c["agent"] for c in configs if isinstance(c, dict) and "agent" in c]
    agents += [yaml.safe_load(p.read_text()) for p in sorted((ROOT / "conf" / "agent").glob("*.yaml"))]
    assert len(agents) > 40
    for agent in agents:
        check_agent(agent)


def test_evaluating_a_shipped_model_writes_outside_models(tmp_path, monkeypatch, capsys):
    """``pathrl-eval run_dir=models/<family>/<name>`` once replaced a committed 1200-episode metrics.json with a
    5-episode one; now its output goes to runs/eval/<name>, and into models/ only with write_models=true."""
    from pathrl.cli.evaluate import main

    monkeypatch.chdir(tmp_path)
    models = ROOT / "models"
    before = _listing(models)
    args = [f"run_dir={model_dir('iiwa7_random')}", "episodes=2", "record=false", "num_envs=2",
            f"dataset.path={ROOT / 'datasets' / 'iiwa7' / 'random'}"]
    assert main(args) == 0
    m = json.loads((tmp_path / "runs" / "eval" / "iiwa7_random" / "metrics.json").read_text())
    assert m["episodes"] == 2 and "wrote runs/eval/iiwa7_random/metrics.json" in capsys.readouterr().out
    assert _listing(models) == before
    # explicit opt-in: a models/ directory of the working directory
    (tmp_path / "models" / "mine").mkdir(parents=True)
    assert main([*args, "out=models/mine"]) == 2 and "write_models=true" in capsys.readouterr().err
    assert main([*args, "out=models/mine", "write_models=true"]) == 0
    assert (tmp_path / "models" / "mine" / "metrics.json").is_file()
    assert os.listdir(tmp_path / "models" / "mine") == ["metrics.json"]


def test_the_library_evaluation_of_a_shipped_model_writes_outside_models(tmp_path, monkeypatch):
    """:func:`pathrl.eval.evaluate.evaluate` as pathrl-eval: a shipped model's metrics go to runs/eval/<name> by
    default, and an out_dir inside models/ is refused (before any work) unless write_models."""
    from pathrl.eval.evaluate import EvalOptions, evaluate, output_dir_of
    from pathrl.runs import RunError

    monkeypatch.chdir(tmp_path)
    model = model_dir("iiwa7_random")
    assert output_dir_of(model) == Path("runs", "eval", "iiwa7_random")
    assert output_dir_of(tmp_path / "run") == tmp_path / "run"
    assert output_dir_of(model, tmp_path / "e") == tmp_path / "e"
    before = _listing(ROOT / "models")
    with pytest.raises(RunError, match="write_models"):
        evaluate(model, EvalOptions(out_dir=model))
    opts = EvalOptions(dataset_path=str(ROOT / "datasets" / "iiwa7" / "random"), episodes=2, num_envs=2,
                       record=False, progress=False)
    assert evaluate(model, opts)["episodes"] == 2
    assert (tmp_path / "runs" / "eval" / "iiwa7_random" / "metrics.json").is_file()
    assert _listing(ROOT / "models") == before
