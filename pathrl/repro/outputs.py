"""What `make reproduce-tables` writes from the results in its output directory: tables.md, tables.csv, tables.tex
and figures/*.png (every table, also those whose rows were not evaluated this time)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from pathrl.config.paper import load as load_paper
from pathrl.models import model_path
from pathrl.repro import trueadapt as adapt
from pathrl.repro.figures import CURVES, learning_curves, pareto_table_ii, path_overlay
from pathrl.repro.layout import ROOT, Layout, Profile
from pathrl.repro.render import render_latex, render_markdown
from pathrl.repro.steps import path_change_file, shipped
from pathrl.repro.tables import PATH_CHANGE, REALTIME, baselines, evaluations, training_record, warm_chain
from pathrl.storage import atomic_write
from pathrl.train.ship import read_curve

__all__ = ["OVERLAYS", "PAPER", "collect", "write_outputs"]

#: The paper's tables (pathrl/config/paper/tracking.yaml), as the renderers take them.
PAPER = load_paper("tracking").as_dict()
#: Evaluations whose episodes are drawn as example path overlays (one per robot).
OVERLAYS = {"iiwa7_random_track_distill": "KUKA iiwa 7, random path",
            "armar6_random_track_distill": "ARMAR-6, random path", "armar4_random": "ARMAR-4 (fixed base), random path"}


def _json_files(files: dict[str, Path]) -> dict[str, Any]:
    """{key: the JSON of its file} of the files that exist."""
    return {k: json.loads(p.read_text()) for k, p in files.items() if p.is_file()}


def collect(lay: Layout) -> dict[str, Any]:
    """Every metrics.json of a shipped policy and every TOPP-RA report of this output directory (an evaluation of a
    policy that was since removed from ``models/`` is not shown), the training records, path changes, real-time
    measurements and the TrueAdapt table's results (:func:`pathrl.repro.trueadapt.collect`)."""
    raw = lay.out / "raw"
    res: dict[str, Any] = {
        "evaluations": _json_files({e.id: raw / e.id / "metrics.json" for e in evaluations() if shipped(e, lay)}),
        "baselines": _json_files({b.id: raw / f"{b.id}.json" for b in baselines()}), "training": {}}
    for model in dict.fromkeys(m for e in evaluations() for m in (*warm_chain(e.model), e.model)):
        if (record := training_record(model_path(model, lay.models))) is not None:
            res["training"][model] = record
    res["path_change"] = _json_files({key: path_change_file(lay, key) for key, _, _ in PATH_CHANGE})
    res["realtime"] = _json_files({key: raw / f"realtime_{key}.json" for key, _, _ in REALTIME})
    res.update(adapt.collect(raw, ROOT / "models", ROOT / "results" / "trueadapt_from_scratch"))
    res["training"].update(res.pop("trueadapt_training"))
    return res


def _write(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, text)


def write_outputs(lay: Layout, profile: Profile) -> str:
    """Render every table from the results in ``lay.out`` into tables.md / .csv / .tex and figures/ (atomically);
    returns the markdown."""
    res = collect(lay)
    md, rows = render_markdown(res, PAPER, profile.name)
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    _write(lay.out / "tables.md", md)
    _write(lay.out / "tables.csv", buf.getvalue())
    _write(lay.out / "tables.tex", render_latex(res, PAPER))
    figs = lay.out / "figures"
    pareto_table_ii(res, PAPER, figs / "pareto_table_II.png")
    for eid, title in OVERLAYS.items():
        mcap = lay.out / "raw" / eid / "episodes.mcap"
        if eid in res["evaluations"] and mcap.is_file():
            path_overlay(mcap, res["evaluations"][eid], title, figs / f"paths_{eid}.png")
    for name, (title, models) in CURVES.items():
        files = {m: model_path(m, lay.models) / "curve.csv" for m in models}
        curves = {m: read_curve(f) for m, f in files.items() if f.is_file()}
        learning_curves(curves, title, figs / f"learning_curve_{name}.png")
    return md

