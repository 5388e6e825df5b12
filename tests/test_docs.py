"""The shell commands and links of README.md, docs/*.md and docs/lab/*.md, checked against the project (issue 23).

Every ```bash block is split into commands (backslash continuations joined, ``#`` comments dropped). Each command
must name what exists, checked without running anything long:

- ``pathrl-*`` (bare or ``.venv/bin/``) is a script of pyproject.toml's [project.scripts], and its arguments pass
  the CLI's own parsing and checks: the CLI's ``main`` runs in-process with the expensive call (dataset
  generation, TOPP-RA, evaluation, export) replaced by a stub that stops it; ``pathrl-train`` runs its pre-check
  (Hydra composition with the schema, env and reward values), a sweep (``-m``) composes every job's overrides;
- ``python FILE``: ``examples/`` scripts run to the end, ``tools/`` scripts declare (argparse) every ``--flag``
  the docs use;
- ``make ...``: ``make -n`` accepts it and every ``VAR=`` is read by the Makefile;
- arguments under models/, datasets/, tools/, examples/ and conf/ exist.

Placeholders (``<run>``, ``SRC_DIR``, ``...``) are checked by their key only. Every project script's ``--help``
runs once. Relative links must point to existing files and headings.
"""

from __future__ import annotations

import contextlib
import io
import itertools
import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
FENCE = re.compile(r"^```([\w-]*)[ \t]*\n(.*?)^```", re.M | re.S)
CHECKED_PREFIXES = ("models/", "datasets/", "tools/", "examples/", "conf/")
TUTORIAL = "docs/your_robot.md"  # run end to end by tests/test_tutorial.py


@dataclass(frozen=True)
class Command:
    where: str  # file:line of the command's first line
    argv: tuple[str, ...]


class _Parsed(BaseException):  # not an Exception: a batch reports those per line and goes on
    """Raised by the stubs: the CLI got past its argument and config checks."""


def doc_files() -> list[Path]:
    """README.md, the user pages docs/*.md and the lab notes docs/lab/*.md."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "lab").glob("*.md"))]


def commands_in(text: str, name: str) -> list[Command]:
    """The commands of the ```bash blocks of one markdown text."""
    out: list[Command] = []
    for m in FENCE.finditer(text):
        if m.group(1) != "bash":
            continue
        first = text.count("\n", 0, m.start(2)) + 1
        logical, start = "", None
        for i, raw in enumerate(m.group(2).splitlines()):
            start = first + i if start is None else start
            if raw.rstrip().endswith("\\"):
                logical += raw.rstrip()[:-1] + " "
                continue
            argv = shlex.split(logical + raw, comments=True)
            if argv:
                out.append(Command(f"{name}:{start}", tuple(argv)))
            logical, start = "", None
    return out


def all_commands() -> list[Command]:
    return [c for p in doc_files() for c in commands_in(p.read_text(), str(p.relative_to(ROOT)))]


def program_of(argv: tuple[str, ...]) -> tuple[str, list[str]]:
    """(program name, arguments), without leading ``VAR=value`` assignments, ``time`` and ``.venv/bin/``."""
    args = list(argv)
    while args and (re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", args[0]) or args[0] == "time"):
        args.pop(0)
    if not args:  # a line of shell assignments only (RUN=...): the command using it cannot be checked
        raise ValueError(f"{' '.join(argv)!r}: a docs command sets shell variables; write the values in")
    prog = args[0]
    if prog.startswith(".venv/bin/"):
        prog = prog[len(".venv/bin/"):]
    return prog, args[1:]


def is_placeholder(token: str) -> bool:
    """``<run>``, ``...``, ``[_test2]`` or an upper-case word such as ``SRC_DIR`` in a path."""
    if re.search(r"<[^>]*>|\.\.\.|\[", token):
        return True
    return any(re.fullmatch(r"[A-Z][A-Z0-9_]*", part) for part in token.split("/"))


def scripts() -> dict[str, str]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]


def missing_paths(args: list[str]) -> list[str]:
    """Arguments (or ``key=value`` values) under the committed dirs that do not exist."""
    values = [a.split("=", 1)[1] if "=" in a and not a.startswith("-") else a for a in args]
    return [v for v in values if v.startswith(CHECKED_PREFIXES) and not is_placeholder(v) and not (ROOT / v).exists()]


# ---------------------------------------------------------------------------------------------------------------
# per-CLI checks (in-process, expensive calls stubbed)


def _stop(*_args, **_kwargs):
    raise _Parsed


def _run_main(main, args: list[str]) -> None:
    """Run a CLI's ``main(argv)``: it must reach the stub (or finish with exit code 0)."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            code = main(args)
    except _Parsed:
        return
    if code != 0:
        raise AssertionError(f"exit code {code}: {err.getvalue().strip()}")


def _split_placeholders(args: list[str]) -> tuple[list[str], list[str]]:
    concrete = [a for a in args if not is_placeholder(a.split("=", 1)[-1])]
    return concrete, [a for a in args if a not in concrete]


def _check_keys_exist(cfg, overrides: list[str]) -> None:
    """Overrides with a placeholder value: the key is a config group or a key of the composed config."""
    from omegaconf import OmegaConf

    absent = object()
    for ov in overrides:
        key, _, value = ov.partition("=")
        key = key.lstrip("+~").split("@")[0]
        if (ROOT / "conf" / key).is_dir():  # a group: some option must fit the pattern, e.g. <row>_length<weight>
            pattern = re.sub(r"<[^>]*>", "*", value)
            if not list((ROOT / "conf" / key).glob(f"{pattern}.yaml")):
                raise AssertionError(f"no option of conf/{key}/ fits {value!r}")
            continue
        if key.startswith("hydra/"):
            continue
        if OmegaConf.select(cfg, key, default=absent) is absent:
            raise AssertionError(f"unknown config key {key!r}")


def _sweep_jobs(overrides: list[str]) -> list[list[str]]:
    """Hydra multirun: one override list per job (comma-separated values expanded)."""
    options = [[f"{o.split('=', 1)[0]}={v}" for v in o.split("=", 1)[1].split(",")] if "=" in o else [o]
               for o in overrides]
    return [list(job) for job in itertools.product(*options)]


def check_train(args: list[str], capsys) -> None:
    from pathrl.cli import train
    from pathrl.cli.common import compose
    from pathrl.schema import TrainAppCfg

    concrete, deferred = _split_placeholders(args)
    if "-m" in concrete or "--multirun" in concrete:
        overrides = [a for a in concrete if a not in ("-m", "--multirun")]
        for job in _sweep_jobs(overrides):
            cfg = compose("train", job, TrainAppCfg)
    else:
        try:
            train._precheck(concrete)
        except SystemExit as exc:
            raise AssertionError(capsys.readouterr().err.strip() or f"exit {exc.code}") from None
        cfg = compose("train", concrete, TrainAppCfg)
    _check_keys_exist(cfg, deferred)


def check_toppra(args: list[str], monkeypatch) -> None:
    import pathrl.dataset.io
    from pathrl.cli import toppra

    monkeypatch.setattr(pathrl.dataset.io, "load_dataset", _stop)
    _run_main(toppra.main, args)


def check_dataset(args: list[str], monkeypatch) -> None:
    import pathrl.datagen.generate
    import pathrl.dataset.io
    import pathrl.dataset.kiemel
    import pathrl.dataset.waypoints
    from pathrl.cli import dataset

    monkeypatch.setattr(pathrl.datagen.generate, "generate_dataset", _stop)
    monkeypatch.setattr(pathrl.dataset.kiemel, "import_kiemel", _stop)
    monkeypatch.setattr(pathrl.dataset.waypoints, "import_waypoints", _stop)
    monkeypatch.setattr(pathrl.dataset.io, "load_dataset", _stop)
    _run_main(dataset.main, args)


def check_eval(args: list[str], monkeypatch) -> None:
    import pathrl.eval.evaluate
    from pathrl.cli import evaluate

    monkeypatch.setattr(pathrl.eval.evaluate, "evaluate", _stop)
    _run_main(evaluate.main, args)


def check_export(args: list[str], monkeypatch) -> None:
    import pathrl.deploy.export
    from pathrl.cli import export

    monkeypatch.setattr(pathrl.deploy.export, "export_policy", _stop)
    _run_main(export.main, args)


def check_view(args: list[str], monkeypatch) -> None:
    from pathrl.cli import view

    view.build_parser().parse_args(args)  # a bad flag is a UserError


CLI_CHECKS = {"pathrl-train": check_train, "pathrl-toppra": check_toppra, "pathrl-dataset": check_dataset,
              "pathrl-eval": check_eval, "pathrl-export": check_export, "pathrl-view": check_view}


# ---------------------------------------------------------------------------------------------------------------
# tests


def test_docs_have_commands() -> None:
    cmds = all_commands()
    assert len(cmds) >= 20, f"only {len(cmds)} commands found in ```bash blocks"
    assert {"make reproduce-tables", "make test"} <= {" ".join(c.argv) for c in cmds}


def test_commands_are_in_bash_fences() -> None:
    """Commands outside ```bash blocks (indented or other fences) would escape the checks below."""
    cmd = re.compile(r"^\s*(\.venv/bin/|pathrl-\w|python tools/|make \w)")
    bad = []
    for p in doc_files():
        text = p.read_text()
        fenced = {text.count("\n", 0, m.start()) + i + 1 for m in FENCE.finditer(text)
                  for i in range(m.group(0).count("\n") + 1) if m.group(1) == "bash"}
        for n, line in enumerate(text.splitlines(), 1):
            if n not in fenced and line.startswith("    ") and cmd.match(line):
                bad.append(f"{p.relative_to(ROOT)}:{n}: {line.strip()}")
        bad += [f"{p.relative_to(ROOT)}: a ```{m.group(1)} block holds commands" for m in FENCE.finditer(text)
                if m.group(1) != "bash" and any(cmd.match(ln) for ln in m.group(2).splitlines())]
    assert not bad, "put these commands into ```bash blocks:\n" + "\n".join(bad)


@pytest.mark.parametrize("cmd", [c for c in all_commands() if program_of(c.argv)[0].startswith("pathrl-")],
                         ids=lambda c: c.where)
def test_pathrl_command(cmd: Command, monkeypatch, capsys) -> None:
    prog, args = program_of(cmd.argv)
    assert prog in scripts(), f"{cmd.where}: {prog} is not in pyproject.toml [project.scripts]"
    assert not missing_paths(args), f"{cmd.where}: missing {missing_paths(args)}"
    check = CLI_CHECKS.get(prog)
    if check is None:
        pytest.skip(f"{prog}: no argument check yet (its --help runs in test_every_cli_help)")
    if cmd.where.startswith(TUTORIAL):  # later steps use the run and datasets of earlier ones
        pytest.skip(f"{TUTORIAL}: every command runs for real, in order, in tests/test_tutorial.py")
    monkeypatch.chdir(ROOT)
    monkeypatch.setenv("PATHRL_ROBOT_PATH", str(ROOT / "examples" / "robots"))  # docs/your_robot.md's robots
    try:
        if prog == "pathrl-train":
            check(args, capsys)
        else:
            check(args, monkeypatch)
    except Exception as exc:  # report which doc line is wrong
        raise AssertionError(f"{cmd.where}: {' '.join(cmd.argv)}\n  -> {type(exc).__name__}: {exc}") from None


def test_other_commands() -> None:
    """``make``, ``python FILE`` and shell scripts: known targets and files; the rest is an unchecked program."""
    makefile = (ROOT / "Makefile").read_text()
    unknown = []
    for cmd in all_commands():
        prog, args = program_of(cmd.argv)
        if prog.startswith("pathrl-"):
            continue
        assert not missing_paths(args + [prog]), f"{cmd.where}: missing {missing_paths(args + [prog])}"
        if prog == "make":
            variables = [a.split("=", 1)[0] for a in args if "=" in a]
            assert all(f"$({v})" in makefile for v in variables), f"{cmd.where}: a variable the Makefile ignores"
            dry = subprocess.run(["make", "-n", *args], cwd=ROOT, capture_output=True, text=True, timeout=60)
            assert dry.returncode == 0, f"{cmd.where}: {dry.stderr.strip()}"
        elif prog in ("python", "python3"):
            assert args and (ROOT / args[0]).is_file(), f"{cmd.where}: no such script {args[:1]}"
        elif prog == "export":  # the robot path of docs/your_robot.md (test_pathrl_command sets it)
            assert args == ["PATHRL_ROBOT_PATH=$PWD/examples/robots"], f"{cmd.where}: export {args}"
        elif not (ROOT / prog).is_file():
            unknown.append(f"{cmd.where}: {prog}")
    assert not unknown, "commands no test checks (add a check to tests/test_docs.py):\n" + "\n".join(unknown)


def _python_scripts() -> dict[str, set[str]]:
    """Each ``python FILE`` of the docs with the ``--flags`` used with it."""
    found: dict[str, set[str]] = {}
    for cmd in all_commands():
        prog, args = program_of(cmd.argv)
        if prog in ("python", "python3") and args:
            found.setdefault(args[0], set()).update(a.split("=")[0] for a in args[1:] if a.startswith("--"))
    return found


def _in_process_help(name: str, entry: str, capsys) -> str | None:
    """``main(["--help"])`` of a script whose ``main`` takes argv: None if it printed usage and exited 0, else
    what went wrong; "subprocess" for a ``main()`` without argv (Hydra apps read sys.argv)."""
    import importlib
    import inspect

    module, func = entry.split(":")
    main = getattr(importlib.import_module(module), func)
    if not inspect.signature(main).parameters:
        return "subprocess"
    try:
        code = main(["--help"])
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr().out
    return None if code in (0, None) and out.strip() else f"{name} --help: exit {code}, output {out[:80]!r}"


def argparse_flags(script: Path) -> set[str]:
    """The ``--flags`` a script declares with ``add_argument`` (read from its source, not imported)."""
    import ast

    flags = set()
    for node in ast.walk(ast.parse(script.read_text())):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument":
            flags |= {a.value for a in node.args if isinstance(a, ast.Constant) and str(a.value).startswith("--")}
    return flags


def test_tools_flags() -> None:
    """Every ``--flag`` the docs pass to a ``tools/`` script is one its argument parser declares."""
    bad = []
    for script, used in _python_scripts().items():
        if script.startswith("tools/"):
            declared = argparse_flags(ROOT / script)
            bad += [f"{script} {flag}" for flag in sorted(used - declared)]
    assert not bad, "flags the scripts do not declare: " + ", ".join(bad)


def test_scripts_and_help(capsys) -> None:
    """Every project script is installed and prints its ``--help`` (in-process where ``main`` takes argv, else as a
    subprocess); ``examples/`` scripts of the docs run to the end (subprocesses, at once)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    failures = [f"{name}: not installed in {BIN}" for name in scripts() if not (BIN / name).is_file()]
    jobs = {}
    for name, entry in scripts().items():
        problem = _in_process_help(name, entry, capsys)
        if problem == "subprocess":
            jobs[f"{name} --help"] = [str(BIN / name), "--help"]
        elif problem:
            failures.append(problem)
    for script in _python_scripts():
        if script.startswith("examples/"):
            jobs[f"python {script}"] = [sys.executable, script]
    procs = {k: subprocess.Popen(v, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for k, v in jobs.items()}
    for key, proc in procs.items():
        out, err = proc.communicate(timeout=180)
        if proc.returncode != 0 or not out.strip():
            failures.append(f"{key}: exit {proc.returncode}: {err.strip().splitlines()[-1:]}")
    assert not failures, "\n".join(failures)


# ---------------------------------------------------------------------------------------------------------------
# links


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text())
    seen: dict[str, int] = {}
    out = set()
    for m in re.finditer(r"^#{1,6}\s+(.+?)\s*$", text, re.M):
        base = slug(m.group(1))
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


def test_links_resolve() -> None:
    bad = []
    for page in doc_files():
        text = FENCE.sub("", page.read_text())
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            file, _, anchor = target.partition("#")
            dest = (page.parent / file).resolve() if file else page
            if not dest.exists():
                bad.append(f"{page.relative_to(ROOT)}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{page.relative_to(ROOT)}: {target} (no such heading)")
    assert not bad, "\n".join(bad)


def test_layout_names_every_dir() -> None:
    """README's layout tree names every top-level directory and every pathrl package that git tracks."""
    listed = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True)
    if listed.returncode != 0:
        pytest.skip("not a git checkout")
    readme = (ROOT / "README.md").read_text()
    tree = next(m.group(2) for m in FENCE.finditer(readme) if readme.rfind("## Layout", 0, m.start()) != -1)
    parts = [Path(f).parts for f in listed.stdout.splitlines()]
    dirs = {p[0] for p in parts if len(p) > 1} | {f"pathrl/{p[1]}" for p in parts if p[0] == "pathrl" and len(p) > 2}
    missing = sorted(d for d in dirs if f"{Path(d).name}/" not in tree)
    assert not missing, f"README's layout does not name {missing}"
