"""docs/your_robot.md run as written, in order, with tiny budgets (issue 49: "the tutorial runs in make test").

The page's fenced blocks are executed in a scratch directory (``examples/`` linked into it, so the page's relative
paths hold): the ```yaml robot file is written where its first comment says and checked; every ```bash command is
run (the CLIs in-process, ``pathrl-train`` as a subprocess; ``export VAR=...`` sets the variable), with tiny budgets
substituted for the page's (:data:`TINY`); the ```python loop runs with a stand-in robot. A command this test does
not know fails it, so the page cannot grow a step that is not run. After each step the test asserts what it left
behind, not only its exit code: the datasets and their paths, the run with the law-tracker teacher (the DAgger
recipe), 0 limit violations in the evaluation, the TOPP-RA solution, the exported actor, the Rerun recordings, and
the loop ending at rest on the CSV's last waypoint (0.005 rad) with 0 limit violations at 500 Hz.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch
import yaml

from pathrl.robot.model import RobotSpec

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
PAGE = ROOT / "docs" / "your_robot.md"
FENCE = re.compile(r"^```([\w-]*)[ \t]*\n(.*?)^```", re.M | re.S)

#: Budget overrides (key=value) per command, replacing the page's value of the key or added to the command.
TINY = {
    ("pathrl-dataset", "generate"): ["dataset.num_train=2", "dataset.num_test=1", "workers=1"],
    ("pathrl-train", None): ["iterations=1", "env.num_envs=16", "agent.num_steps_per_env=8", "compile_limits=false",
                             "threads=1"],
    ("pathrl-toppra", None): ["workers=1"],
    ("pathrl-export", None): ["observations=50"],
}
CONTROL_RATE = 500.0  # Hz, the page's loop


def blocks(text: str) -> list[tuple[str, str]]:
    """The page's fenced blocks in order: (language, body)."""
    return [(m.group(1), m.group(2)) for m in FENCE.finditer(text)]


def commands(body: str) -> list[list[str]]:
    """The commands of a ```bash block (continuation lines joined, comments dropped)."""
    out, logical = [], ""
    for raw in body.splitlines():
        if raw.rstrip().endswith("\\"):
            logical += raw.rstrip()[:-1] + " "
            continue
        argv = shlex.split(logical + raw, comments=True)
        logical = ""
        if argv:
            out.append(argv)
    return out


def with_budget(prog: str, args: list[str]) -> list[str]:
    """`args` with the tiny budget of `prog` (and its subcommand): values of the same key replaced, others added."""
    sub = args[0] if args and not args[0].startswith("-") and "=" not in args[0] else None
    tiny = TINY.get((prog, sub), TINY.get((prog, None), []))
    keys = {t.split("=", 1)[0]: t for t in tiny}
    out = [keys.pop(a.split("=", 1)[0], a) if "=" in a else a for a in args]
    return out + list(keys.values())


class StandInRobot:
    """The page's ``robot``: it reads back the last position sent (no lag) and keeps every setpoint sent."""

    def __init__(self, q0: np.ndarray, max_sends: int = 1000):
        self.q, self.sent, self.max_sends = np.asarray(q0, dtype=np.float64), [], max_sends

    def read_position(self) -> np.ndarray:
        """The robot's joint positions (D,) (rad): the last setpoint sent."""
        return self.q

    def send(self, position: np.ndarray, velocity: np.ndarray) -> None:
        """One decision's setpoints, (C, D) each."""
        assert position.shape == velocity.shape and position.shape[0] == int(CONTROL_RATE * 0.1)
        self.sent.append(position)
        self.q = position[-1]
        if len(self.sent) > self.max_sends:
            raise RuntimeError(f"the loop did not end within {self.max_sends} decisions")


def _waypoints(robot: RobotSpec) -> np.ndarray:
    """Six waypoints (K, M) of a curved joint-space path well inside the robot's position range (rad)."""
    lim = robot.pos_limits[robot.path_index]
    t = np.linspace(0.0, 1.0, 6)[:, None]
    frac = 0.35 + 0.3 * t + 0.1 * np.sin(np.pi * t) * np.linspace(-1.0, 1.0, lim.shape[0])
    return lim[:, 0] + frac * (lim[:, 1] - lim[:, 0])


def _run_cli(prog: str, args: list[str], capsys) -> str:
    """A ``pathrl-*`` command in-process (``pathrl-train`` as a subprocess: its Hydra app reads sys.argv); exit 0
    asserted; its standard output."""
    if prog == "pathrl-train":
        done = subprocess.run([str(BIN / prog), *args], env={**os.environ, "OMP_NUM_THREADS": "1"},
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        return done.stdout
    module = {"pathrl-robot": "robot", "pathrl-dataset": "dataset", "pathrl-eval": "evaluate",
              "pathrl-toppra": "toppra", "pathrl-export": "export", "pathrl-view": "view"}[prog]
    main = importlib.import_module(f"pathrl.cli.{module}").main
    code = main(args)
    out, err = capsys.readouterr()
    assert code == 0, f"{prog} {' '.join(args)}: exit {code}: {err[-2000:]}"
    return out


def _run_example(args: list[str], capsys) -> str:
    """``python examples/FILE.py ARGS``: the script's ``main(*ARGS)`` in-process; its standard output."""
    spec = importlib.util.spec_from_file_location("tutorial_example", Path(args[0]))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(*args[1:])
    return capsys.readouterr().out


def _check_outcome(prog: str, args: list[str], out: str, knots: np.ndarray | None) -> None:
    """What the command left behind in the scratch directory (relative paths: the page's)."""
    from pathrl.dataset.io import load_dataset
    from pathrl.robot.external import load_robot_by_name

    kv = dict(a.split("=", 1) for a in args if "=" in a and not a.startswith("-"))
    if prog == "pathrl-robot" and args[0] == "check":
        assert out.rstrip().endswith("ok"), out
    elif prog == "pathrl-dataset" and args[0] == "generate":
        spec = load_robot_by_name(kv["robot"])
        ds = load_dataset(kv["dataset.path"], spec)
        assert [len(ds.splits[s].knots) for s in ("train", "test")] == [2, 1]
    elif prog == "pathrl-dataset" and args[0] == "import":
        spec = load_robot_by_name(args[args.index("--robot") + 1])
        test = load_dataset(args[-1], spec).splits["test"]
        assert len(test.knots) == 1 and np.allclose(test.knots[0], knots, atol=1e-12)
    elif prog == "pathrl-train":
        cfg = yaml.safe_load((Path(kv["run_dir"]) / "config.yaml").read_text())
        assert cfg["teacher"]["name"] == "law_tracker" and cfg["agent"]["algorithm"]["class_name"] == "Distillation"
        assert cfg["robot"]["name"] == kv["robot"] and "position_limits" in cfg["robot"]  # the expanded robot
        assert list(Path(kv["run_dir"]).glob("model_*.pt"))
    elif prog == "pathrl-eval":
        metrics = json.loads((Path(kv["run_dir"]) / "metrics.json").read_text())
        assert metrics["episodes"] >= 1 and metrics["limit_violations"] == 0
    elif prog == "pathrl-toppra":
        sol = json.loads((Path(kv["dataset.path"]) / "toppra_test_full.json").read_text())
        assert sol["episodes"] >= 1 and sol["solved"] == sol["episodes"] and sol["toppra_duration_s"] > 0
    elif prog == "pathrl-export":
        export = Path(kv["run_dir"]) / "export"
        assert all((export / f).stat().st_size > 0 for f in ("actor.pt", "actor.onnx", "export.json"))
    elif prog == "pathrl-view":
        assert all((Path(args[0]) / f).stat().st_size > 0 for f in ("episodes.rrd", "run.rrd"))


def _run_loop(body: str, knots: np.ndarray, monkeypatch) -> None:
    """The page's ```python loop with a stand-in robot: every setpoint recorded, checked against every limit."""
    from pathrl.deploy import Follower
    from pathrl.deploy.follower import SETTLE_TOLERANCE
    from pathrl.limits.check import limit_violations
    from pathrl.limits.feasible import JointLimits

    decided = []
    decide = Follower.decide

    def recorded(self, *a, **kw):
        sp = decide(self, *a, **kw)
        decided.append(sp)
        return sp

    monkeypatch.setattr(Follower, "decide", recorded)
    robot = StandInRobot(knots[0])
    scope = {"robot": robot}
    exec(compile(body, str(PAGE), "exec"), scope)  # noqa: S102 - the page's own code
    follower = scope["follower"]
    assert follower.done and follower.final_error <= SETTLE_TOLERANCE
    assert np.abs(robot.sent[-1][-1] - knots[-1]).max() <= SETTLE_TOLERANCE  # at the CSV's last waypoint
    assert follower.measured_error == 0.0  # the stand-in reads back what it was sent
    start = [torch.as_tensor(knots[0])[None]] + [torch.zeros(1, len(knots[0]))] * 2  # at rest on the first waypoint
    p, v, a = (torch.cat([s] + [torch.as_tensor(getattr(sp, f)) for sp in decided]).to(torch.float64)
               for s, f in zip(start, ("position", "velocity", "acceleration"), strict=True))
    bad = limit_violations(p[None], v[None], a[None], JointLimits.from_robot(follower.robot), 1.0 / CONTROL_RATE)
    assert int(bad["total"][0]) == 0, {k: int(x.sum()) for k, x in bad.items()}


def test_the_tutorial_runs_as_written(tmp_path, monkeypatch, capsys):
    from pathrl.robot.external import expand_robot_file, load_robot_by_name

    (tmp_path / "examples").symlink_to(ROOT / "examples")
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("PATHRL_ROBOT_PATH", raising=False)
    ran: list[str] = []
    knots = None
    for lang, body in blocks(PAGE.read_text()):
        if lang == "yaml":  # the robot file: written where its first line says, then checked
            target = tmp_path / re.match(r"#\s*(\S+\.yaml)", body).group(1)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(body)
            shipped = expand_robot_file(ROOT / "examples" / "robots" / "panda.yaml")
            assert expand_robot_file(target)["acceleration_limits"] == shipped["acceleration_limits"]
            _check_outcome("pathrl-robot", ["check"], _run_cli("pathrl-robot", ["check", str(target)], capsys), None)
            ran.append("robot file")
        elif lang == "python":
            assert knots is not None, "the loop follows the CSV path of section 2"
            np.savetxt("my_path.csv", knots, delimiter=",")
            _run_loop(body, knots, monkeypatch)
            ran.append("python loop")
        elif lang == "bash":
            for argv in commands(body):
                prog = argv[0].removeprefix(".venv/bin/")
                args = [a.replace("$PWD", str(tmp_path)) for a in argv[1:]]
                if prog == "export":
                    key, value = args[0].split("=", 1)
                    monkeypatch.setenv(key, value)
                    ran.append(f"export {key}")
                    continue
                if prog == "python" and args[0].startswith("examples/"):
                    out = _run_example(args, capsys)
                    assert ", 0 limit violations" in out and "at rest on the last waypoint" in out, out
                    ran.append(f"python {args[0]}")
                    continue
                assert prog.startswith("pathrl-"), f"{PAGE.name}: {' '.join(argv)}: a command this test does not run"
                args = with_budget(prog, args)
                if prog == "pathrl-dataset" and args[0] == "import":  # MY_PATHS: one CSV path
                    knots = _waypoints(load_robot_by_name(args[args.index("--robot") + 1]))
                    Path(args[-2]).mkdir()
                    np.savetxt(Path(args[-2]) / "line.csv", knots, delimiter=",")
                _check_outcome(prog, args, _run_cli(prog, args, capsys), knots)
                ran.append(f"{prog} {args[0]}" if prog in ("pathrl-robot", "pathrl-dataset") else prog)
    assert ran == ["robot file", "export PATHRL_ROBOT_PATH", "pathrl-robot check", "pathrl-robot list",
                   "pathrl-dataset generate", "pathrl-dataset generate", "pathrl-dataset import", "pathrl-train",
                   "pathrl-eval", "pathrl-toppra",
                   "python loop", "python examples/control_loop_rates.py", "pathrl-export", "pathrl-view"]
