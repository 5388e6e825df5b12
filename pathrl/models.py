"""The shipped models: one directory ``models/<family>/<name>/`` each (config.yaml, weights, summary.json), found
by name.

The families are the task families: ``tracking`` (path tracking: the policies, the greedy followers and the
model-based controllers of its feedback tasks), ``trueadapt`` (TrueAdapt trajectory adaptation, its tray
controllers and references too) and ``industrial`` (the industrial motion-profile optimisation). A shipped model's
family is the folder it is in; a name not shipped yet (a training's destination) takes the family its name says:
``iiwa7_trueadapt_*`` TrueAdapt, ``industrial_*`` industrial, every other tracking.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["FAMILIES", "MODELS", "ModelError", "family_of", "model_dir", "model_name", "model_path", "model_ref",
           "regrouped", "shipped"]

#: The checkout's ``models/``.
MODELS = Path(__file__).resolve().parents[1] / "models"

#: The folders of ``models/``, one per task family.
FAMILIES = ("tracking", "trueadapt", "industrial")

#: Name prefixes of the families other than tracking (for a name not shipped yet).
_PREFIXES = (("iiwa7_trueadapt_", "trueadapt"), ("industrial_", "industrial"))


class ModelError(ValueError):
    """An unknown or malformed model name or reference (one line)."""


def _checked(name: str) -> str:
    """`name` if it is a plain model name (no path separator, not empty)."""
    if not isinstance(name, str) or not name or "/" in name or "\\" in name or name in (".", ".."):
        raise ModelError(f"model name must be a plain directory name like iiwa7_random, got {name!r}")
    return name


def family_of(name: str, models: Path = MODELS) -> str:
    """The family of the model `name`: the folder of `models` that holds it, else the one its name says."""
    found = [f for f in FAMILIES if (Path(models) / f / _checked(name)).is_dir()]
    if len(found) > 1:
        raise ModelError(f"model {name!r} is shipped in several families: {', '.join(found)}")
    return found[0] if found else next((f for prefix, f in _PREFIXES if name.startswith(prefix)), "tracking")


def model_path(name: str, models: Path = MODELS) -> Path:
    """``<models>/<family>/<name>``, shipped or not (where a training ships it)."""
    return Path(models) / family_of(name, models) / name


def model_dir(name: str, models: Path = MODELS) -> Path:
    """The directory of the shipped model `name`; ModelError if none of the families has it."""
    path = model_path(name, models)
    if not path.is_dir():
        raise ModelError(f"unknown model {name!r}: no {'|'.join(FAMILIES)} folder of {models} holds it")
    return path


def model_ref(name: str, models: Path = MODELS) -> str:
    """``models/<family>/<name>``: how commands and configs run from the checkout name the model `name`."""
    return f"models/{family_of(name, models)}/{name}"


def model_name(ref: str) -> str:
    """The model name of a reference ``models/<family>/<name>`` (a trailing slash allowed); ModelError otherwise."""
    parts = str(ref).rstrip("/").split("/")
    if len(parts) != 3 or parts[0] != "models" or parts[1] not in FAMILIES or not parts[2]:
        raise ModelError(f"expected models/<family>/<name> with family one of {', '.join(FAMILIES)}, got {ref!r}")
    return parts[2]


def regrouped(path: str | Path) -> Path | None:
    """For a flat ``<...>/models/<name>`` path (the layout before the family folders) of a shipped model, its
    ``<...>/models/<family>/<name>``; None for any other path."""
    p = Path(path)
    if p.parent.name != "models" or p.name in FAMILIES or p.is_dir():
        return None
    found = [p.parent / f / p.name for f in FAMILIES if (p.parent / f / p.name).is_dir()]
    return found[0] if len(found) == 1 else None


def shipped(models: Path = MODELS) -> list[Path]:
    """Every shipped model directory, family by family, in name order."""
    return [p for f in FAMILIES for p in sorted((Path(models) / f).glob("*")) if p.is_dir()]
