"""``pathrl-view``: Rerun recordings of evaluation episodes (``episodes.mcap``) and runs (``run.mcap``).

    pathrl-view PATH [--save OUT.rrd] [--spawn | --serve] [--episodes 0,5,17 | --worst N]
                [--timeline time|episode]

Every family's recordings (:mod:`pathrl.families`: each names its files and their converter) are served the same
way. PATH is a run directory (its ``episodes.mcap`` and/or ``run.mcap``; ``industrial.mcap`` of ``pathrl-industrial
record``, ``trueadapt.mcap`` of ``tools/trueadapt_record.py``) or one of those files. Each MCAP becomes
one ``.rrd`` next to it (``episodes.rrd`` / ``run.rrd``; a selection ``episodes_worst5.rrd`` /
``episodes_ep0-5-17.rrd``, so the full recording is never replaced by a part of it) unless ``--save`` names the
output (only when a single file is converted). Outputs are checked before anything is converted. The viewer is
started only on request: ``--spawn`` (native window) or ``--serve`` (web viewer, like ``rerun --serve-web``; blocks
until Ctrl-C).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from pathrl.cli.common import UserError, output_file, run_cli
from pathrl.logging.mcap_io import is_finished

__all__ = ["build_parser", "default_output", "inputs_of", "main", "parse_ids"]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (run_cli)
        raise UserError(f"{message} (see pathrl-view --help)")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``pathrl-view`` (errors raise UserError)."""
    p = _Parser(prog="pathrl-view", description="Convert pathrl MCAP logs into Rerun recordings (.rrd).")
    p.add_argument("path", type=Path, help="run directory, episodes.mcap, run.mcap, industrial.mcap or trueadapt.mcap")
    p.add_argument("--save", type=Path, metavar="OUT.rrd", help="output file (default: next to each input)")
    view = p.add_mutually_exclusive_group()
    view.add_argument("--spawn", action="store_true", help="open the native Rerun viewer on the result")
    view.add_argument("--serve", action="store_true", help="serve the result in Rerun's web viewer")
    p.add_argument("--port", type=int, default=9090, help="web viewer port for --serve (default 9090)")
    sel = p.add_mutually_exclusive_group()
    sel.add_argument("--episodes", metavar="IDS", help="comma-separated episode ids, e.g. 0,5,17")
    sel.add_argument(
        "--worst", type=int, metavar="N", help="the N episodes with the largest cart_pos_dev_mean_cm"
    )
    p.add_argument(
        "--timeline",
        choices=("time", "episode"),
        default="time",
        help="timeline the viewer opens on (default: time)",
    )
    return p


def parse_ids(text: str) -> list[int]:
    """Episode ids from ``--episodes`` text like ``0,5,17`` (order kept, duplicates dropped); UserError if malformed or
    negative."""
    try:
        ids = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise UserError(f"--episodes expects comma-separated integers like 0,5,17, got {text!r}") from None
    if not ids or any(i < 0 for i in ids):
        raise UserError(f"--episodes expects non-negative episode ids like 0,5,17, got {text!r}")
    return list(dict.fromkeys(ids))


def inputs_of(path: Path) -> list[tuple[str, Path]]:
    """[(kind, mcap)] to convert for PATH (a run directory or an MCAP file)."""
    from pathrl.families import file_names
    from pathrl.viz.rerun_view import kind_of

    if not path.exists():
        raise UserError(f"no such file or directory: {path}")
    if path.is_dir():
        names = file_names()  # every family's recordings
        found = [path / n for n in names if (path / n).is_file()]
        if not found:
            raise UserError(f"{path}: no {', '.join(names)} in this directory")
        return [(kind_of(f), f) for f in found]
    return [(kind_of(path), path)]


def default_output(src: Path, ids: list[int] | None, worst: int | None) -> Path:
    """The ``.rrd`` beside `src`: ``episodes.rrd`` for all episodes, ``episodes_worst<N>.rrd`` or
    ``episodes_ep<id>-<id>....rrd`` for a selection (a part never replaces the whole recording)."""
    if worst is not None:
        return src.with_name(f"{src.stem}_worst{worst}.rrd")
    if ids is not None:
        shown = "-".join(map(str, ids[:8])) + (f"-and-{len(ids) - 8}-more" if len(ids) > 8 else "")
        return src.with_name(f"{src.stem}_ep{shown}.rrd")
    return src.with_suffix(".rrd")


def _main(argv: list[str]) -> None:
    from pathrl.families import ViewOptions, recording_of, resolve
    from pathrl.viz import rerun_view as rv

    args = build_parser().parse_args(argv)
    ids = parse_ids(args.episodes) if args.episodes is not None else None
    if args.worst is not None and args.worst < 1:
        raise UserError(f"--worst must be >= 1, got {args.worst}")
    if args.spawn and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise UserError(
            "--spawn needs a display (DISPLAY/WAYLAND_DISPLAY unset); use --serve or open the .rrd elsewhere"
        )
    if args.save is not None:
        output_file(args.save, "--save")
        if not args.save.parent.is_dir():
            raise UserError(f"--save {args.save}: directory {args.save.parent} does not exist")
    try:
        jobs = inputs_of(args.path)
        if args.save is not None and len(jobs) > 1:
            raise UserError(
                f"{args.path} has {' and '.join(s.name for _, s in jobs)}; --save takes one input (pass the file)"
            )
        recs = {kind: recording_of(kind) for kind, _ in jobs}
        if (ids is not None or args.worst is not None) and not any(r.selectable for r in recs.values()):
            raise UserError(f"--episodes/--worst need an episodes.mcap; {args.path} has none")
        sel = {kind: r.selectable for kind, r in recs.items()}
        targets = [(kind, src, args.save or default_output(src, ids if sel[kind] else None,
                                                           args.worst if sel[kind] else None))
                   for kind, src in jobs]
        for _, _, out in targets:
            output_file(out, "--save" if args.save else "output")
        outs = []
        view = ViewOptions(ids, args.worst, args.timeline)
        for kind, src, out in targets:
            if not is_finished(src):
                print(f"warning: {src} ends without the MCAP footer (cut off, or a run killed or still writing); "
                      "converting what is readable", file=sys.stderr)
            stats = resolve(recs[kind].view)(src, out, view)
            what = f"{stats.items} {recs[kind].items}"
            for note in stats.warnings:
                print(f"warning: {note}", file=sys.stderr)
            print(f"wrote {out} ({what}, {stats.bytes / 1e6:.1f} MB, {stats.seconds:.1f} s)")
            outs.append(out)
    except rv.ViewError as exc:
        raise UserError(str(exc)) from None
    except OSError as exc:
        raise UserError(f"{exc.filename or args.path}: {exc.strerror or exc}") from None
    if args.spawn:
        rv.spawn_viewer(outs)
        print("opened the Rerun viewer")
    elif args.serve:
        print(
            f"serving with `rerun --serve-web` on port {args.port}; open the URL it prints (Ctrl-C to stop)",
            flush=True,
        )
        rv.serve_web(outs, port=args.port)
    else:
        print("open with: " + " ".join(["rerun", *map(str, outs)]))


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``pathrl-view PATH [options]`` (argv: sys.argv[1:]); returns the exit code."""
    return run_cli(_main, argv)


if __name__ == "__main__":
    raise SystemExit(main())
