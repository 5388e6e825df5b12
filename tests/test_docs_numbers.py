"""Every number the README's headline section and `docs/results.md` state has a receipt: a committed file holding
it, within the rounding the text shows.

Receipts: `results/tables.csv` (ours and the paper's value of every table cell, written by `make reproduce-tables`),
`results/raw/` (that command's per-evaluation results), `results/receipts/` (evaluations of shipped policies outside
the tables), `results/time_to_quality/` and `models/*/summary.json` (training records). `RECEIPTS` below lists, per
page, passages quoted verbatim and one source per number in them, in order. The test fails when

- a quoted number is not its file's value at the quoted number of decimals (a drifted result or an edited page);
- a passage is no longer on its page (the page was edited: update its receipt with it);
- a number on the page stands in no listed passage (a new claim without a receipt);
- a receipt in `results/receipts/` was made from model or test-split files that have changed since.

Numbers are decimal tokens outside code spans and link targets, not part of a name (iiwa7, ARMAR-6, i7-8700K).
"""
from __future__ import annotations

import csv
import functools
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"

# -- sources: each returns the value a quoted number stands for ----------------------------------------------------

Source = Callable[[], float]

TABLES = {
    "I": "table_I_tracking_no_feedback", "I2": "table_I_second_test_set", "II": "table_II_tradeoff_length_vs_deviation",
    "III": "table_III_knots_in_state", "IV": "table_IV_generalization_random_to_target_point",
    "VI": "table_VI_toppra_timing", "VII": "table_VII_ball_on_plate", "VIII": "table_VIII_armar4_balance",
    "IX": "table_IX_computation_time", "PC": "path_adjustments", "TA": "trueadapt_table_I",
}


@functools.cache
def _csv() -> dict[tuple[str, str, str], tuple[str, str]]:
    with open(RESULTS / "tables.csv", newline="") as f:
        return {(r["table"], r["row"], r["metric"]): (r["ours"], r["paper"]) for r in csv.DictReader(f)}


@functools.cache
def _json(path: str) -> dict:
    return json.loads((ROOT / path).read_text())


def _dig(d, key: str):
    for part in key.split("."):
        d = d[int(part)] if isinstance(d, list) else d[part]
    return d


def t(table: str, row: str, metric: str) -> Source:
    """Our value of a cell of results/tables.csv."""
    return lambda: float(_csv()[(TABLES[table], row, metric)][0])


def p(table: str, row: str, metric: str) -> Source:
    """The paper's value of a cell of results/tables.csv."""
    return lambda: float(_csv()[(TABLES[table], row, metric)][1])


def raw(evaluation: str, key: str, scale: float = 1.0) -> Source:
    """A key of results/raw/<evaluation>/metrics.json, or of results/raw/<evaluation> when it names a .json file,
    times `scale` (100: m to cm, a share to %)."""
    path = f"results/raw/{evaluation}" if evaluation.endswith(".json") else f"results/raw/{evaluation}/metrics.json"
    return lambda: float(_dig(_json(path), key)) * scale


def rcp(receipt: str, key: str) -> Source:
    """A metric of results/receipts/<receipt>.json."""
    return lambda: float(_json(f"results/receipts/{receipt}.json")["metrics"][key])


def summary(model: str, key: str, scale: float = 1.0) -> Source:
    """A key of models/<model>/summary.json (training records), times `scale` (1/60: seconds to minutes)."""
    return lambda: float(_dig(_json(f"models/{model}/summary.json"), key)) * scale


def minutes(*models: str) -> Source:
    """Training wall time of the models together, in minutes."""
    return lambda: sum(float(_json(f"models/{m}/summary.json")["wall_time_s"]) for m in models) / 60


def file(path: str, key: str, scale: float = 1.0) -> Source:
    """A key of any committed JSON file (dotted path; list indices as numbers)."""
    return lambda: float(_dig(_json(path), key)) * scale


def ratio(a: Source, b: Source) -> Source:
    return lambda: a() / b()


def const(value: float, why: str) -> Source:
    """Not a measurement: a protocol or config value (a count, a window, a bound), with the reason."""
    assert why
    return lambda: value


def tolerance(slack: float, src: Source) -> Source:
    """A number quoted as approximate ("about"): accepted within `slack` beyond its rounding."""
    src.slack = slack  # type: ignore[attr-defined]
    return src


# -- the passages ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Receipt:
    doc: str
    text: str
    sources: tuple[Source, ...]


def R(doc: str, text: str, *sources: Source) -> Receipt:
    return Receipt(doc, text, sources)


README = "README.md"
RES = "docs/results.md"

RECEIPTS: list[Receipt] = [
    # README.md, "Headline result"
    R(README, "iiwa7 random, 1200 paper-protocol segments", raw("iiwa7_random_track_distill", "episodes")),
    R(README, "in 2 min to the paper's quality and 25 min in all",
      file("results/time_to_quality/iiwa7_random_distill/curve.json", "runs.0.minutes_to_target"),
      minutes("iiwa7_random_track_distill")),
    R(README, "| 2.97 | 0 | 0 / 0 | 0 |", t("VI", "iiwa7/random", "toppra_duration_s"),
      *[raw("toppra_iiwa7_random_paper.json", "toppra_max_joint_dev_rad")] * 3,  # on the path: no deviation
      raw("toppra_iiwa7_random_paper.json", "limit_violations")),
    R(README, "| **3.32** | 0.062 | **1.79** / 4.50 | 0 |", t("I", "iiwa7/random", "duration_s"),
      t("I", "iiwa7/random", "joint_dev_mean_rad"), t("I", "iiwa7/random", "cart_pos_dev_mean_cm"),
      t("I", "iiwa7/random", "cart_pos_dev_max_cm"), raw("iiwa7_random_track_distill", "limit_violations")),
    R(README, "(`models/iiwa7_random`) | 3.91 | 0.100 | 2.92 / 6.96 | 0 |",
      *[raw("iiwa7_random", k) for k in ("duration_s", "joint_dev_mean_rad", "cart_pos_dev_mean_cm",
                                         "cart_pos_dev_max_cm", "limit_violations")]),
    R(README, "path length weight 6, then 9 (`models/iiwa7_random_fast`) | 3.63 | 0.116 | 3.31 / 7.92 | 0 |",
      const(6, "config: conf/experiment/iiwa7_random_continue.yaml"), const(9, "config: iiwa7_random_fast.yaml"),
      *[rcp("iiwa7_random_fast", k) for k in ("duration_s", "joint_dev_mean_rad", "cart_pos_dev_mean_cm",
                                              "cart_pos_dev_max_cm", "limit_violations")]),
    R(README, "| 4.81 | 0.086 | 2.52 / 6.06 | 0 |",
      *[raw("iiwa7_random_length_eq_deviation", k) for k in ("duration_s", "joint_dev_mean_rad",
                                                             "cart_pos_dev_mean_cm", "cart_pos_dev_max_cm",
                                                             "limit_violations")]),
    R(README, "their TOPP-RA 3.36 s) | 4.28 | 0.11 | 3.3 / 7.5 |", p("VI", "iiwa7/random", "toppra_duration_s"),
      p("I", "iiwa7/random", "duration_s"), p("I", "iiwa7/random", "joint_dev_mean_rad"),
      p("I", "iiwa7/random", "cart_pos_dev_mean_cm"), p("I", "iiwa7/random", "cart_pos_dev_max_cm")),
    R(README, "the student is 1.12x TOPP-RA",
      ratio(t("I", "iiwa7/random", "duration_s"), t("VI", "iiwa7/random", "toppra_duration_s"))),
    R(README, "the best PPO policy 1.22x",
      ratio(rcp("iiwa7_random_fast", "duration_s"), t("VI", "iiwa7/random", "toppra_duration_s"))),
    R(README, "1.99 s at 0.75 cm, by PPO 2.15 s at\n2.93 cm, paper 2.44 s at 1.4 cm",
      t("I", "iiwa7/ball_balancing", "duration_s"), t("I", "iiwa7/ball_balancing", "cart_pos_dev_mean_cm"),
      rcp("iiwa7_ball_balancing_length_lt", "duration_s"), rcp("iiwa7_ball_balancing_length_lt", "cart_pos_dev_mean_cm"),
      p("I", "iiwa7/ball_balancing", "duration_s"), p("I", "iiwa7/ball_balancing", "cart_pos_dev_mean_cm")),
    R(README, "(Table VII, 200 whole test paths in PyBullet)", raw("iiwa7_ball_balancing_residual_in_pybullet", "episodes")),
    R(README, "loses no ball (0.0 %) at 2.93 s (paper: 0.3 % at\n2.99 s)",
      t("VII", "residual_path_law_ppo", "ball_fell_pct"), t("VII", "residual_path_law_ppo", "duration_end_of_path_s"),
      p("VII", "balancing_reward", "ball_fell_pct"), p("VII", "balancing_reward", "duration_end_of_path_s")),
    R(README, "0.0 % falls on the table's 200 episodes,\n99 % of which reach the end of the path in time, at 5.38 s "
              "(paper's learned legs: 0.8 % at 5.59 s)",
      t("VIII", "controlled_legs/balance_fast", "fell_pct"), raw("armar4_legs_balance_fast_in_pybullet", "episodes"),
      t("VIII", "controlled_legs/balance_fast", "reached_end_pct"),
      t("VIII", "controlled_legs/balance_fast", "duration_end_of_path_s"),
      p("VIII", "controlled_legs/balancing_reward", "fell_pct"),
      p("VIII", "controlled_legs/balancing_reward", "duration_end_of_path_s")),
    R(README, "(32.8 M steps,\n29 min on one thread;", summary("iiwa7_trueadapt_on_plate_ppo_scratch", "env_steps", 1e-6),
      minutes("iiwa7_trueadapt_on_plate_ppo_scratch")),
    R(README, "ball on 99.9 % of 1000 test trajectories on a plate in PyBullet (paper 89.6 %;",
      t("TA", "on_plate/test_set_scratch", "success_pct"),
      raw("iiwa7_trueadapt_on_plate_ppo_scratch_in_pybullet", "episodes"),
      p("TA", "on_plate/test_set_scratch", "success_pct")),
    R(README, "keeps 98.6 % at 0.66 cm from its\nstart (paper 98.6 % at 1.2 cm;",
      t("TA", "in_place/test_set_ppo", "success_pct"),
      raw("iiwa7_trueadapt_in_place_ppo_in_pybullet", "offset", 100),
      p("TA", "in_place/test_set_ppo", "success_pct"), p("TA", "in_place/test_set_ppo", "error_distance_cm")),
    R(README, "ARMAR-4 on random paths by PPO: 4.66 s at 2.73 cm", rcp("armar4_random_bias", "duration_s"),
      rcp("armar4_random_bias", "cart_pos_dev_mean_cm")),
    R(README, "takes 3.27 s at 1.77 cm\n(paper 5.09 s at 3.3 cm)", t("I", "armar4_fixed/random", "duration_s"),
      t("I", "armar4_fixed/random", "cart_pos_dev_mean_cm"), p("I", "armar4_fixed/random", "duration_s"),
      p("I", "armar4_fixed/random", "cart_pos_dev_mean_cm")),
]

# -- checking -------------------------------------------------------------------------------------------------------

# the part of each page whose numbers need receipts
SECTIONS = {README: ("## Headline result", "## Where results live"), RES: ("", None)}

NUMBER = re.compile(r"(?<![\w.])(?<![A-Za-z]-)[-+]?\d+(?:\.\d+)?(?![\w.]*[A-Za-wyz_])")


def _blank(text: str) -> str:
    """`text` with code spans and link targets blanked out (same length, so positions stay)."""
    def sp(m: re.Match) -> str:
        return " " * len(m.group(0))
    text = re.sub(r"`[^`\n]*`", sp, text)
    return re.sub(r"\]\([^)\s]*\)", lambda m: "]" + " " * (len(m.group(0)) - 1), text)


def numbers(text: str) -> list[tuple[int, str]]:
    return [(m.start(), m.group(0)) for m in NUMBER.finditer(_blank(text))]


def _section(doc: str) -> tuple[str, int]:
    text = (ROOT / doc).read_text()
    start, end = SECTIONS[doc]
    a = text.index(start) if start else 0
    b = text.index(end, a) if end else len(text)
    return text[a:b], a


def matches(quoted: str, value: float, slack: float = 0.0) -> bool:
    q = quoted.lstrip("+")
    decimals = len(q.split(".")[1]) if "." in q else 0
    return abs(value - float(q)) <= 0.5 * 10 ** -decimals + slack + 1e-9


def test_every_receipt_matches_its_file():
    bad = []
    for r in RECEIPTS:
        nums = numbers(r.text)
        if len(nums) != len(r.sources):
            bad.append(f"{r.doc}: {r.text!r}: {len(nums)} numbers, {len(r.sources)} sources")
            continue
        for (_, q), src in zip(nums, r.sources):
            try:
                value = src()
            except (KeyError, FileNotFoundError, IndexError) as e:
                bad.append(f"{r.doc}: {r.text!r}: {q}: no such result ({e!r})")
                continue
            if not matches(q, value, getattr(src, "slack", 0.0)):
                bad.append(f"{r.doc}: {r.text!r}: quotes {q}, its file says {value:.6g}")
    assert not bad, "numbers that do not match their receipts:\n" + "\n".join(bad)


def test_every_passage_is_on_its_page():
    missing = [f"{r.doc}: {r.text!r}" for r in RECEIPTS if r.text not in _section(r.doc)[0]]
    assert not missing, "receipted passages no longer on their page (update RECEIPTS):\n" + "\n".join(missing)


@pytest.mark.parametrize("doc", list(SECTIONS))
def test_every_number_has_a_receipt(doc):
    text, _ = _section(doc)
    covered = [False] * len(text)
    for r in RECEIPTS:
        if r.doc != doc:
            continue
        for m in re.finditer(re.escape(r.text), text):
            covered[m.start():m.end()] = [True] * (m.end() - m.start())
    loose = []
    for pos, q in numbers(text):
        if not covered[pos]:
            line = text.count("\n", 0, pos) + 1
            ctx = text[max(0, pos - 40):pos + 20].replace("\n", " ")
            loose.append(f"{doc} (section line {line}): {q!r} in ...{ctx}...")
    assert not loose, "numbers without a receipt (add one to RECEIPTS or take the claim out):\n" + "\n".join(loose)


def test_receipts_were_made_from_the_committed_files():
    from pathrl.repro.inputs import fingerprint

    stale = []
    for path in sorted((RESULTS / "receipts").glob("*.json")):
        rec = json.loads(path.read_text())
        m = rec["metrics"]
        model = ROOT / m["run_dir"]
        now = fingerprint(ROOT, model, ROOT / m["dataset"])
        if now != rec["inputs"]:
            changed = sorted(k for k in set(now) | set(rec["inputs"]) if now.get(k) != rec["inputs"].get(k))
            stale.append(f"{path.name}: {changed}")
    assert not stale, "receipts made from files that have changed since (re-run their command):\n" + "\n".join(stale)


def test_the_checker_catches_a_drifted_number():
    r = R(RES, "at 3.32 s", t("I", "iiwa7/random", "duration_s"))
    (_, q), = numbers(r.text)
    assert matches(q, r.sources[0]())
    assert not matches("3.30", r.sources[0]())
    assert [q for _, q in numbers("ARMAR-6 on iiwa7, 1.12x, 5.46-5.51 s, i7-8700K, `seed=1`, -4.5 to +10 cm")] == [
        "1.12", "5.46", "5.51", "-4.5", "+10"]
