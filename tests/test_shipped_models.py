"""The shipped models' layout, ``models/<family>/<name>/``, and its one resolver (:mod:`pathrl.models`)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from pathrl.models import (
    FAMILIES,
    MODELS,
    ModelError,
    family_of,
    model_dir,
    model_name,
    model_path,
    model_ref,
    regrouped,
    shipped,
)

ROOT = Path(__file__).resolve().parents[1]

#: Committed records that name the paths they were made with (evaluation outputs, benchmark results): left as made;
#: and this file, whose flat paths are the cases.
RECORDS = re.compile(r"^(results/raw/|results/industrial_|results/your_robot/|results/trueadapt_from_scratch/|bench/"
                     r"|tests/test_shipped_models\.py)")


def test_models_holds_the_family_folders_only():
    assert sorted(p.name for p in MODELS.iterdir()) == sorted(FAMILIES)
    names = [p.name for p in shipped()]
    assert len(names) == len(set(names)) > 90, "a model name is shipped in two families"


def test_every_model_is_in_the_family_its_name_says():
    """A shipped model's folder agrees with the rule for names not shipped yet (a training's destination)."""
    for path in shipped():
        assert family_of(path.name, Path("/nonexistent")) == path.parent.name, path


def test_resolver_finds_by_name_and_refuses_unknown_names():
    assert model_dir("iiwa7_random") == MODELS / "tracking" / "iiwa7_random"
    assert model_dir("iiwa7_trueadapt_on_plate_tray_controller").parent.name == "trueadapt"
    assert model_dir("industrial_td3").parent.name == "industrial"
    assert model_ref("greedy_iiwa7_random") == "models/tracking/greedy_iiwa7_random"
    assert model_path("iiwa7_trueadapt_not_yet") == MODELS / "trueadapt" / "iiwa7_trueadapt_not_yet"
    with pytest.raises(ModelError, match="unknown model 'nope'"):
        model_dir("nope")
    with pytest.raises(ModelError, match="plain directory name"):
        model_dir("tracking/iiwa7_random")


def test_model_name_of_a_reference():
    assert model_name("models/tracking/iiwa7_random/") == "iiwa7_random"
    for bad in ("models/iiwa7_random", "models/other/x", "runs/x/seed0"):
        with pytest.raises(ModelError, match="expected models/<family>/<name>"):
            model_name(bad)


def test_a_flat_path_points_to_its_family_folder():
    assert regrouped("models/iiwa7_random") == Path("models/tracking/iiwa7_random")
    assert regrouped(MODELS / "industrial_td3") == MODELS / "industrial" / "industrial_td3"
    assert regrouped("models/tracking/iiwa7_random") is None and regrouped("models/nope") is None


def test_no_file_names_a_model_by_its_flat_path():
    """Code, configs, docs and receipts name ``models/<family>/<name>``, never the flat ``models/<name>``."""
    names = "|".join(sorted((re.escape(p.name) for p in shipped()), key=len, reverse=True))
    flat = re.compile(rf"(?<![\w/])models/({names})(?!\w)")
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    offenders = []
    for name in files:
        path = ROOT / name
        if RECORDS.match(name) or path.suffix in (".pt", ".npz", ".png", ".mcap", ".onnx") or not path.is_file():
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        offenders += [f"{name}: {m.group(0)}" for m in flat.finditer(text)]
    assert offenders == []
