"""The benchmarks' console tables (rich) of the results :mod:`pathrl.bench.suite` writes."""

from __future__ import annotations

from pathlib import Path

__all__ = ["print_follower", "print_results"]

def print_follower(res: dict) -> None:
    """The follower latencies of a bench result `res` (``bench/follower.json``'s content) as a table on the console."""
    from rich.console import Console
    from rich.table import Table

    load = res["machine"].get("load_avg_start")
    t = Table(title="pathrl.deploy.Follower, 1 thread (wall clock; CPU time of the thread)"
              + (f", load {load[0]:g} at the start" if load else ""))
    t.add_column("benchmark")
    t.add_column("result", justify="right")
    _follower_rows(t, res)
    Console().print(t)


def _follower_rows(t, res: dict) -> None:
    """Rows of the follower benchmarks."""
    for k in sorted(k for k in res if k.startswith("follower_") and "decisions" in res[k]):
        d = res[k]
        t.add_row(f"Follower.decide, {d['model']}",
                  f"{d['mean_ms']:.2f} ms mean, p99 {d['p99_ms']:.2f} (CPU p99 {d['cpu_p99_ms']:.2f})")
        for kind in ("knots", "prepared"):
            r = d.get(f"replace_path_{kind}")
            if r:
                t.add_row(f"Follower.replace_path ({kind}), {d['model']}",
                          f"{r['mean_ms']:.2f} ms mean, p99 {r['p99_ms']:.2f} (CPU p99 {r['cpu_p99_ms']:.2f})")
    for k in sorted(k for k in res if k.startswith("follower_end_")):
        d = res[k]
        t.add_row(f"Follower to the end, {d['model']}, {d['paths']} test paths at {d['rate_hz']:g} Hz",
                  f"final error max {d['final_error_max']:.1e} rad, {d['violations']} violations, "
                  f"{d['not_done']} not done, approach mean {d['approach_mean_s']:.2f} s")
    f = res.get("follower_fuzz_iiwa7_random")
    if f:
        t.add_row(f"Follower fuzz, {Path(f['model']).name}: {f['trials']} adversarial paths ({f['refused']} refused "
                  f"unclipped, all followed clipped), {f['path_changes']} path changes "
                  f"({f.get('path_changes_refused', 0)} refused), {f['stops']} stops, {f['bad_states_refused']} bad "
                  f"states refused, {f.get('measured_states', 0)} measured states ({f.get('measured_refused', 0)} "
                  f"refused, {f.get('measured_mishandled', 0)} mishandled), {f['crashes']} crashes",
                  f"{f['violations']} violations in {f['setpoints_checked']:,} setpoint values")


def print_results(res: dict, out: Path) -> None:
    """Every benchmark of a result `res` (written to `out`) as a table on the console."""
    from rich.console import Console
    from rich.table import Table

    t = Table(title=f"pathrl benchmarks -> {out}")
    t.add_column("benchmark")
    t.add_column("result", justify="right")
    for key in sorted(k for k in res if k.startswith("env_")):
        e = res[key]
        native_t = f" (native code {e['native_threads']})" if e.get("native_threads") else ""
        t.add_row(f"env {e['robot']}, {e['num_envs']} envs, limits {e['limits']}, torch {e['threads']} thread(s)"
                  f"{native_t}",
                  f"{e['env_steps_per_s']:,.0f} steps/s")
    t.add_row("single-env reference iiwa7", f"{res['reference_iiwa7']['env_steps_per_s']:,.0f} steps/s")
    t.add_row("batched / reference (iiwa7)", f"{res['batched_over_reference_iiwa7']:,.0f} x")
    if res["ppo_iteration_iiwa7"]["hidden_dtype"] == "float32":  # main() found bfloat16 emulated
        t.add_row("bfloat16 hidden layers: emulated on this CPU, not timed",
                  f"{res['bfloat16_over_float32_layer']:.0f} x float32")
    for key in sorted(k for k in res if k.startswith("ppo_iteration_")):
        p = res[key]
        share = ", ".join(f"{k} {100 * v:.0f} %" for k, v in p["share"].items())
        t.add_row(f"PPO iteration {p['robot']} ({p['num_envs']} envs x {p['steps_per_env']} steps), hidden "
                  f"{p['hidden_dtype']}, {p['threads']} thread(s): {share}",
                  f"{p['s_per_iteration']:.2f} s, {p['samples_per_s']:,.0f} samples/s")
    for k in ("ball_task_analytic", "ball_task_pybullet"):
        b = res[k]
        t.add_row(f"ball task, {b['backend']}, {b['num_envs']} envs", f"{b['env_steps_per_s']:,.0f} steps/s")
    t.add_row("ball task analytic / PyBullet", f"{res['ball_task_analytic_over_pybullet']:,.0f} x")
    t.add_row("kinematic tracking env (2 cores) / PyBullet ball env (2 workers)",
              f"{res['kinematic_tracking_over_pybullet_ball']:,.0f} x")
    t.add_row("kinematic tracking env (1 thread) / PyBullet ball env (2 workers)",
              f"{res['kinematic_tracking_1thread_over_pybullet_ball']:,.0f} x")
    for k in sorted(k for k in res if k.startswith("decision_")):
        d = res[k]
        t.add_row(f"policy + limits per decision, {d['robot']}, limits {d['limits']}",
                  f"{d['mean_ms']:.2f} ms (max {d['max_pct_of_step']:.1f} % of 0.1 s)")
    _follower_rows(t, res)
    d = res["trueadapt_decision"]
    t.add_row(f"TrueAdapt decision (policy + valid range + setpoints), {Path(d['model']).name}, 1 thread",
              f"{d['decision_ms_mean']:.2f} ms mean (max {d['decision_ms_max']:.2f}; valid range max "
              f"{d['valid_range_ms_max']:.2f})")
    for k in ("physics_ball_on_plate", "physics_armar4_standing"):
        d = res[k]
        t.add_row(f"PyBullet {d['scene']} (one client)", f"{d['physics_steps_per_s']:,.0f} physics steps/s "
                  f"({d['decisions_per_s']:,.1f} decisions/s)")
    Console().print(t)
