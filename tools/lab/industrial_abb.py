"""The calibrated controller model (issue 47): curve-1 calibration table and ILC / constant-gain rows.

    .venv/bin/python tools/lab/industrial_abb.py calibrate   # -> results/industrial_abb_calibration.md
    .venv/bin/python tools/lab/industrial_abb.py ilc         # -> results/industrial_abb_ilc.md
    .venv/bin/python tools/lab/industrial_abb.py mpgd_gain   # -> results/industrial_abb_mpgd_gain.md
    .venv/bin/python tools/lab/industrial_abb.py table2 RUN_DIR [OUT.md]  # -> results/industrial_abb_table2.md
    .venv/bin/python tools/lab/industrial_abb.py table3 RUN_DIR [V_MAX_FACTOR]  # -> results/industrial_abb_table3.md
    .venv/bin/python tools/lab/industrial_abb.py critic RUN_DIR/model_K.pt  # the critic vs the one-step reward

``table2`` runs MPGD, both ILC variants (``ILCColumns``: the gains as tuned by ``ilc``, 1 and 1) and the policy of
RUN_DIR on the nine rows and reports executions per row, ratios as means of per-row ratios with totals beside,
t_opt measured and under the paper's cost model, and the distribution of the policy's first actions a1-a3.

``ilc`` tunes each ILC variant's gain on training-family curves (``rl_train.training_target``, seeds of the
training draw, never the Table II rows), then runs baseline, P-type ILC, filtered ILC and the constant
error-feedback gains k in {0.5, 1, 2} on the nine Table II rows at their speed commands.
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))


def calibrate() -> str:
    """The curve-1 calibration table (markdown)."""
    from pathrl.industrial import reference as ref
    from pathrl.industrial.controller import ControllerParams, execute

    prog, ctrl = ref.curve1_program(), ControllerParams(model="abb")
    lines = ["| v (mm/s) | figure | recorded | model | model / recorded | target |", "|---|---|---|---|---|---|"]
    for v in (123.05, 300.0):
        t0 = time.perf_counter()
        m = asdict(ref.measure(execute(prog, v, ctrl, seed=0), v))
        wall = time.perf_counter() - t0
        rec = ref.RECORDED[v]
        rows = [("max error (mm)", rec[0], m["max_err"], "+-20 %"),
                ("mean error (mm)", rec[1], m["mean_err"], "+-20 %"),
                ("max orientation error (deg)", rec[2], m["max_ori"], "-"),
                ("mean speed (mm/s)", rec[3], m["mean_speed"], "-"),
                ("speed std (% of mean)", rec[4], m["speed_std_pct"], "<= 1 %" if v < 200 else "-"),
                ("time over the curve (s)", rec[5], m["time_over"], "-"),
                ("rest to 95 % of command (s)", "0.10-0.12" if v < 200 else None, m["ramp95_s"],
                 "<= 0.15" if v < 200 else "-"),
                ("max error at (share of arc length)", "0.80-1.00" if v < 200 else None, m["max_at"], ">= 0.8")]
        for name, r, x, target in rows:
            ratio = f"{x / r:.2f}" if isinstance(r, float) else "-"
            lines.append(f"| {v:g} | {name} | {r if r is not None else '-'} | {x:.3f} | {ratio} | {target} |")
        lines.append(f"| {v:g} | execution wall time (s) | - | {wall:.2f} | - | - |")
    return "\n".join(["# Calibrated controller model (controller.model=abb) on the recorded curve-1 program", "",
                      "`python tools/lab/industrial_abb.py calibrate` (seed 0, one core).", "", *lines, ""])


def ilc() -> str:
    """Gain tuning on training curves and the nine rows (markdown)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.experiments import select_targets
    from pathrl.industrial.ilc import ILCParams, run_ilc, tune_gain
    from pathrl.industrial.rl_train import training_target
    from pathrl.industrial.trajectories import baseline_program

    ctrl = ControllerParams(model="abb")
    train = [training_target(i, seed=7) for i in range(6)]
    out = ["# ILC and constant error feedback on the calibrated model (controller.model=abb)", "",
           "`python tools/lab/industrial_abb.py ilc` (one core). Iterations = updates until the max error is <= 0.5 mm "
           "(0 = the baseline already is; N/A = not within 10 updates); in brackets the best max error (mm).", ""]
    tuned = {}
    for kind in ("p", "filtered"):
        t0 = time.perf_counter()
        best, scores = tune_gain(train, (0.5, 1.0, 1.5), ILCParams(kind=kind, k_max=5), ctrl)
        tuned[kind] = best
        out.append(f"- {kind} ILC gain tuned on 6 training curves (k_max 5; mean iterations, a miss = 6): "
                   + ", ".join(f"{g:g}: {s:.2f}" for g, s in scores.items()) + f" -> **{best:g}** "
                   f"({time.perf_counter() - t0:.0f} s)")
    methods = {"ILC P (tuned)": ILCParams("p", tuned["p"]), "ILC filtered (tuned)": ILCParams("filtered",
                                                                                                 tuned["filtered"])}
    methods.update({f"a = ({k:g}, 0, 0)": ILCParams("p", k) for k in (0.5, 1.0, 2.0)})
    head = "| Traj. | speed (mm/s) | baseline (mm) | " + " | ".join(methods) + " |"
    out += ["", head, "|" + "---|" * (3 + len(methods))]
    for t in select_targets([]):
        prog = baseline_program(t)
        cells, base = [], None
        for p in methods.values():
            r = run_ilc(t, prog, t.speed, p, ctrl)
            base = r.history[0]
            itr = "N/A" if r.iterations_to_spec is None else str(r.iterations_to_spec)
            cells.append(f"{itr} ({r.errors.max_pos_mm:.2f})")
        out.append(f"| {t.name} | {t.speed:.0f} | {base:.2f} | " + " | ".join(cells) + " |")
    return "\n".join(out + [""])


def _ratio_line(name: str, a: list, b: list) -> str:
    """Mean of per-row ratios a_i / b_i and the ratio of totals, over rows where both are known."""
    pairs = [(x, y) for x, y in zip(a, b, strict=True) if x is not None and y is not None]
    if not pairs:
        return f"- {name}: no row reached by both"
    per_row = sum(x / y for x, y in pairs) / len(pairs)
    total = sum(x for x, _ in pairs) / sum(y for _, y in pairs)
    return (f"- {name} on the {len(pairs)} rows both reach: mean of per-row ratios {per_row:.2f}x, ratio of totals "
            f"{total:.2f}x")


def table2(run_dir: str) -> str:
    """Executions per row of MPGD, ILC and the policy on the calibrated model (markdown)."""
    import numpy as np

    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.experiments import select_targets
    from pathrl.industrial.ilc import ILCColumns, run_ilc
    from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
    from pathrl.industrial.mpgd import run_mpgd
    from pathrl.industrial.rl import run_policy_iwa
    from pathrl.industrial.rl_train import load_agent
    from pathrl.industrial.timing import PAPER_EXECUTION_S, PAPER_MPGD_DECISION_S
    from pathrl.industrial.trajectories import baseline_program

    ctrl = ControllerParams(model="abb")
    agent, it = load_agent(Path(run_dir))
    clip = agent.params.action_clip

    def policy(obs: np.ndarray) -> np.ndarray:
        return clip * agent.act(obs)

    methods = ("MPGD", "ILC P", "ILC filtered", "RL")
    execs: dict[str, list] = {m: [] for m in methods}
    errs: dict[str, list] = {m: [] for m in methods}
    walls: dict[str, list] = {m: [] for m in methods}
    first_actions, lines = [], []
    for t in select_targets([]):
        prog = baseline_program(t)
        res = {"MPGD": run_mpgd(t, prog, t.speed, None, ctrl)}
        res.update({name: run_ilc(t, prog, t.speed, p, ctrl) for name, p in ILCColumns().variants("abb").items()})
        env = IWAEpisode(t, t.speed, ctrl, IWASettings(100, 10.0, 10, 2.0))
        res["RL"] = run_policy_iwa(env, policy)
        first_actions.append(policy(IWAEpisode(t, t.speed, ctrl).reset()))
        cells = []
        for m in methods:
            r = res[m]
            n = None if r.iterations_to_spec is None else r.iterations_to_spec + 1
            execs[m].append(n)
            errs[m].append(r.errors.max_pos_mm)
            walls[m].append(r.t_opt)
            cells.append(f"{n if n is not None else 'N/A'} ({r.errors.max_pos_mm:.2f})")
        lines.append(f"| {t.name} | {t.speed:.0f} | {res['MPGD'].history[0]:.2f} | " + " | ".join(cells) + " |")
    out = [f"# Calibrated model (controller.model=abb): executions to 0.5 mm per row, policy {run_dir} "
           f"(iteration {it}, action clip {clip:g})", "",
           f"`python tools/lab/industrial_abb.py table2 {run_dir}` (one core). Executions including the baseline's "
           "(N/A = not within k_max: MPGD 50, ILC and RL 10); best max error (mm) in brackets.", "",
           "| Traj. | speed (mm/s) | baseline (mm) | " + " | ".join(methods) + " |",
           "|" + "---|" * (3 + len(methods)), *lines, ""]
    for m in methods:
        got = [n for n in execs[m] if n is not None]
        mean = f", mean {sum(got) / len(got):.1f} executions" if got else ""
        t_meas = sum(w for w, n in zip(walls[m], execs[m], strict=True) if n is not None)
        t_paper = sum(got) * PAPER_EXECUTION_S
        extra = f" / {t_paper + sum(n - 1 for n in got) * PAPER_MPGD_DECISION_S:.0f} s with 61 s per MPGD " \
            "decision" if m == "MPGD" else ""
        out.append(f"- {m}: {len(got)}/9 rows{mean}; t_opt on the reached rows {t_meas:.1f} s measured, "
                   f"{t_paper:.0f} s at 12 s per execution{extra}")
    out.append(_ratio_line("MPGD / RL executions", execs["MPGD"], execs["RL"]))
    out.append(_ratio_line("ILC filtered / RL executions", execs["ILC filtered"], execs["RL"]))
    out.append(_ratio_line("ILC P / RL executions", execs["ILC P"], execs["RL"]))
    out.append(_ratio_line("MPGD / ILC filtered executions", execs["MPGD"], execs["ILC filtered"]))
    a = np.concatenate(first_actions)
    out += ["", "First actions of the policy on the nine baseline profiles (900 waypoints; a1 along the error, a2 "
            "towards the previous waypoint, a3 their cross product; the clip is +-" + f"{clip:g}):", "",
            "| action | mean | std | 5 % | 50 % | 95 % | share at the clip |", "|---|---|---|---|---|---|---|"]
    for j in range(3):
        q = np.percentile(a[:, j], [5, 50, 95])
        at = np.mean(np.abs(a[:, j]) >= 0.99 * clip)
        out.append(f"| a{j + 1} | {a[:, j].mean():.2f} | {a[:, j].std():.2f} | {q[0]:.2f} | {q[1]:.2f} | {q[2]:.2f} | "
                   f"{100 * at:.0f} % |")
    return "\n".join(out + [""])


def _specs_cells(errs) -> str:
    """Error (mm), orientation (deg), mean speed (mm/s), speed std (%) of one execution, a * on each missed spec."""
    from pathrl.industrial.metrics import ORI_SPEC_DEG, POS_SPEC_MM, SPEED_STD_SPEC

    def mark(bad: bool) -> str:
        return "*" if bad else ""

    return (f"{errs.max_pos_mm:.2f}{mark(errs.max_pos_mm > POS_SPEC_MM)} | {errs.max_ori_deg:.2f}"
            f"{mark(errs.max_ori_deg > ORI_SPEC_DEG)} | {errs.mean_speed:.0f} | {100 * errs.speed_std_ratio:.1f}"
            f"{mark(errs.speed_std_ratio > SPEED_STD_SPEC)}")


def table3(run_dir: str, v_max: float = 2.0) -> str:
    """Table III on the calibrated model: per method (MPGD, both ILC variants, the policy of RUN_DIR) and row the
    IWA at the row's command ("IWA only") and the bisection's fastest command meeting all three specs, searched
    between 0.2 and `v_max` x the row's command (markdown)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.experiments import select_targets, speed_iwa
    from pathrl.industrial.ilc import ILCColumns
    from pathrl.industrial.iwa_env import IWASettings
    from pathrl.industrial.rl_train import load_agent
    from pathrl.industrial.speed_search import SearchParams, bisection_search
    from pathrl.industrial.trajectories import baseline_program

    ctrl, settings = ControllerParams(model="abb"), IWASettings(100, 10.0, 10, 2.0)
    agent, it = load_agent(Path(run_dir))
    clip = agent.params.action_clip
    methods = {"MPGD": {}, **{n: {"ilc": p} for n, p in ILCColumns().variants("abb").items()},
               "RL": {"policy": lambda obs: clip * agent.act(obs)}}
    head = ("| method | Traj. | v cmd | IWA only: error (mm) | ori. (deg) | mean speed (mm/s) | speed std (%) | "
            "bisection: v cmd (mm/s) | error (mm) | ori. (deg) | mean speed (mm/s) | speed std (%) | executions | "
            "wall time (s) |")
    out = ["# Table III on the calibrated model (controller.model=abb): IWA + bisection speed search", "",
           f"`python tools/lab/industrial_abb.py table3 {run_dir} {v_max:g}` (one core; policy iteration {it}, "
           f"action clip "
           f"{clip:g}; MPGD gain 0.5, k_max 50; ILC gains {ILCColumns().gain_p:g} (P) and "
           f"{ILCColumns().gain_filtered:g} (filtered), k_max 10; RL k_max 10; bisection: 10 outer iterations "
           f"between 0.2 and {v_max:g} x the row's command). * = spec missed (0.5 mm, 3 deg, 5 %); N/A = no command "
           "met all "
           "three.", "", head, "|" + "---|" * 14]
    summary = []
    for name, kw in methods.items():
        t0, met, speeds = time.perf_counter(), 0, []
        for t in select_targets([]):
            inner = speed_iwa(t, ctrl, settings, 0, kw.get("policy"), kw.get("ilc"))
            search = SearchParams(v_max_factor=v_max)
            res = bisection_search(t, t.speed, search, None, ctrl, 0, baseline_program(t), inner)
            first = res.trials[0][2].errors
            n_exec = sum(r.executions for _, _, r in res.trials)
            best = "N/A | - | - | - | -" if res.best is None else f"{res.v:.0f} | {_specs_cells(res.best.errors)}"
            met += res.best is not None
            speeds += [] if res.best is None else [res.best.errors.mean_speed / first.mean_speed]
            out.append(f"| {name} | {t.name} | {t.speed:.0f} | {_specs_cells(first)} | {best} | {n_exec} | "
                       f"{res.t_total:.1f} |")
        ratio = f", mean speed {sum(speeds) / len(speeds):.2f}x the IWA-only run's" if speeds else ""
        summary.append(f"- {name}: all three specs met on {met}/9 rows{ratio} ({time.perf_counter() - t0:.0f} s)")
    return "\n".join(out + ["", *summary, ""])


def mpgd_gain() -> str:
    """MPGD's step gain tuned like the ILC gains: 6 training-family curves, fewest mean iterations (markdown)."""
    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.mpgd import MPGDParams, run_mpgd
    from pathrl.industrial.rl_train import training_target
    from pathrl.industrial.trajectories import baseline_program

    ctrl = ControllerParams(model="abb")
    train = [training_target(i, seed=7) for i in range(6)]
    scores = {}
    t0 = time.perf_counter()
    for gain in (0.5, 1.0, 1.5):
        its = [run_mpgd(t, baseline_program(t), t.speed, MPGDParams(k_max=10, gain=gain), ctrl).iterations_to_spec
               for t in train]
        scores[gain] = sum(11 if i is None else i for i in its) / len(its)
    best = min(scores, key=lambda g: (scores[g], g))
    return ("# MPGD step gain on the calibrated model, tuned on 6 training curves (k_max 10; a miss = 11)\n\n"
            + ", ".join(f"{g:g}: {v:.2f}" for g, v in scores.items()) + f" -> **{best:g}** "
            f"({time.perf_counter() - t0:.0f} s)\n")


def critic(ckpt: str) -> str:
    """The critic of a training checkpoint against the measured one-step reward (markdown): on the baseline states
    of 6 training curves, Q1(s, (a1, 0, 0)) and the mean reward of one execution with every waypoint at
    a = clip x (a1, 0, 0), for tanh outputs a1 in 0, 0.25, ..., 1."""
    import numpy as np
    import torch
    from tensordict import TensorDict

    from pathrl.industrial.controller import ControllerParams
    from pathrl.industrial.iwa_env import IWAEpisode, IWASettings
    from pathrl.industrial.rl import RLParams, TD3Agent
    from pathrl.industrial.rl_train import training_target
    from pathrl.storage import load_checkpoint

    state = load_checkpoint(Path(ckpt))
    params = RLParams(**state["params"])
    agent = TD3Agent(params)
    agent.load_state_dict(state["agent"])
    ctrl, grid = ControllerParams(model="abb"), (0.0, 0.25, 0.5, 0.75, 1.0)
    settings = IWASettings(100, 10.0, params.k_max, params.action_clip, params.w_ori, params.success_decay)
    loss = agent.loss

    def q1(obs: np.ndarray, a: np.ndarray) -> float:
        td = TensorDict({"observation": torch.as_tensor(obs, dtype=torch.float32) * agent.mask,
                         "action": torch.as_tensor(a, dtype=torch.float32)}, [len(obs)])
        with torch.no_grad(), loss.qvalue_network_params[0].to_module(loss.qvalue_network):
            return float(loss.qvalue_network(td)["state_action_value"].mean())

    out = [f"# Critic of {ckpt} (iteration {state['iteration']}) against the measured one-step reward", "",
           f"`python tools/lab/industrial_abb.py critic {ckpt}`: baseline states of training curves 0-5 (seed "
           f"{params.seed}); every waypoint at tanh output (a1, 0, 0), i.e. the action {params.action_clip:g} x that.",
           "", "| curve | baseline (mm) | " + " | ".join(f"Q(a1={g:g})" for g in grid) + " | "
           + " | ".join(f"r(a1={g:g})" for g in grid) + " | actor a1 (action units) |", "|" + "---|" * 13]
    for i in range(6):
        t = training_target(i, params.seed)
        obs = IWAEpisode(t, t.speed, ctrl, settings).reset()
        qs, rs = [], []
        for g in grid:
            a = np.tile([g, 0.0, 0.0], (len(obs), 1))
            qs.append(q1(obs, a))
            env = IWAEpisode(t, t.speed, ctrl, settings)
            env.reset()
            rs.append(float(env.step(params.action_clip * a).reward.mean()))
        a1 = params.action_clip * agent.act(obs)[:, 0].mean()
        out.append(f"| train{i} | {float(env.pos0.max()):.2f} | "
                   + " | ".join(f"{x:.2f}" for x in qs) + " | " + " | ".join(f"{x:.2f}" for x in rs)
                   + f" | {a1:.2f} |")
    return "\n".join(out + [""])


def main() -> None:
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what not in ("calibrate", "ilc", "mpgd_gain", "table2", "table3", "critic") or (
            what in ("table2", "table3", "critic") and len(sys.argv) < 3):
        raise SystemExit("usage: tools/lab/industrial_abb.py {calibrate,ilc,mpgd_gain,table2 RUN_DIR [OUT.md],"
                         "table3 RUN_DIR [V_MAX_FACTOR],critic CHECKPOINT}")
    from pathrl.storage import atomic_write

    run = {"calibrate": calibrate, "ilc": ilc, "mpgd_gain": mpgd_gain, "table2": lambda: table2(sys.argv[2]),
           "table3": lambda: table3(sys.argv[2], *map(float, sys.argv[3:4])),
           "critic": lambda: critic(sys.argv[2])}
    text = run[what]()
    if what == "critic":  # a diagnosis: printed, not written
        print(text)
        return
    name = {"calibrate": "calibration", "ilc": "ilc", "mpgd_gain": "mpgd_gain", "table2": "table2",
            "table3": "table3"}[what]
    default = ROOT / "results" / f"industrial_abb_{name}.md"
    path = Path(sys.argv[3]) if what == "table2" and len(sys.argv) > 3 else default
    atomic_write(path, text)
    print(text)


if __name__ == "__main__":
    main()
