"""``python -m pathrl.cli.family_step FAMILY STEP RUN_DIR OUT.json [key=value ...]``: one lifecycle step of a task
family's registry entry (:mod:`pathrl.families`) that returns a result, written to ``OUT.json`` (atomically) and
printed: ``timing`` (realtime timing) or ``validate`` (limit validation; a family without one writes ``null``).

The keys are :class:`pathrl.eval.evaluate.EvalOptions`' (``episodes``, ``num_envs``, ``seed``, ``dataset_path``,
``split``, ``backend``, ``compile_limits``, ``workers``); each step's docstring says what it reads from them, e.g. the
TrueAdapt family's ``validate`` runs ``num_envs`` trajectories of ``episodes`` decision steps. `make
reproduce-tables` runs the TrueAdapt table's limit validation and time per decision so (:mod:`pathrl.repro.trueadapt`).
Evaluations are ``pathrl-eval``'s (every family).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pathrl.cli.common import ArgParser, UserError, output_file, run_cli

__all__ = ["STEPS", "main", "options"]

#: The steps run here (those returning a result; ``evaluate`` is ``pathrl-eval``'s).
STEPS = ("timing", "validate")
_INT, _BOOL, _STR = ("episodes", "num_envs", "seed", "workers"), ("compile_limits",), ("dataset_path", "split",
                                                                                      "backend")


def options(pairs: list[str]) -> dict[str, Any]:
    """``key=value`` pairs as EvalOptions keyword arguments (ints, ``true``/``false``, strings); UserError (one
    line) on an unknown key, a missing ``=`` or a value of the wrong kind."""
    out: dict[str, Any] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or key not in (*_INT, *_BOOL, *_STR):
            raise UserError(f"expected key=value with a key of {', '.join((*_INT, *_BOOL, *_STR))}, got {pair!r}")
        if key in _INT:
            if not value.lstrip("-").isdigit() or int(value) < (0 if key == "seed" else 1):
                raise UserError(f"{key} must be an integer >= {0 if key == 'seed' else 1}, got {value!r}")
            out[key] = int(value)
        elif key in _BOOL:
            if value not in ("true", "false"):
                raise UserError(f"{key} must be true or false, got {value!r}")
            out[key] = value == "true"
        else:
            out[key] = value
    return out


def _main(argv: list[str]) -> None:
    from pathrl.eval.evaluate import EvalOptions
    from pathrl.families import family

    ap = ArgParser(prog="python -m pathrl.cli.family_step", description=__doc__.split("\n\n")[0])
    ap.add_argument("family")
    ap.add_argument("step", choices=STEPS)
    ap.add_argument("run_dir", type=Path, help="a run or model directory of the family")
    ap.add_argument("out", type=Path, help="the result (JSON)")
    ap.add_argument("options", nargs="*", help="key=value (EvalOptions)")
    args = ap.parse_args(argv)
    try:
        fam = family(args.family)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    opts = EvalOptions(progress=False, record=False, **options(args.options))
    out = output_file(args.out, "OUT")
    import torch

    from pathrl.storage import write_json_atomic

    torch.set_num_threads(1)
    res = fam.step(args.step)(args.run_dir, opts)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out, res)
    print(json.dumps(res, indent=1, default=str))


def main(argv: list[str] | None = None) -> int:
    """Entry point (argv: sys.argv[1:]); 0, or 2 with a one-line error on stderr."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
