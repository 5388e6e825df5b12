"""Where `make reproduce-tables` reads and writes, and how much it runs: the profiles and the output layout."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["PROFILES", "ROOT", "Layout", "Profile", "rel"]

#: The checkout: the commands of a reproduction run here, and the shipped models and datasets are read from it.
ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Profile:
    """How much a reproduction runs: paper segments per evaluation (None: the CLIs' default, 1200), the paths of the
    datasets ``--train`` generates, the trainings' overrides and whether limit kernels are compiled."""

    name: str
    episodes: int | None  # paper segments per evaluation (None: the CLIs' default, 1200)
    num_train: int  # paths of generated datasets (--train)
    num_test: int
    train_overrides: tuple[str, ...] = ()
    compile_limits: bool = True  # torch.compile the limit kernels in trainings and real-time measurements


PROFILES = {
    "full": Profile("full", None, 1000, 200),
    "quick": Profile("quick", 12, 12, 4, ("iterations=2", "env.num_envs=64", "agent.num_steps_per_env=8",
                                          "agent.save_interval=1", "threads=1"), compile_limits=False),
}


@dataclass
class Layout:
    """Where a profile reads and writes."""

    out: Path
    models: Path
    runs: Path
    test_data: Path  # <robot>/<dataset> test splits
    train_data: Path  # <robot>/<dataset> datasets with a train split (--train)

    @classmethod
    def of(cls, profile: Profile, out: Path, train: bool) -> Layout:
        """The layout of `profile` writing to `out`: a quick profile with `train` is self-contained under `out`
        (tiny datasets, runs and models), every other reads the checkout's models and datasets."""
        if profile.name == "quick" and train:
            return cls(out, out / "models", out / "runs", out / "data", out / "data")
        return cls(out, ROOT / "models", ROOT / "runs", ROOT / "datasets", ROOT / "data")


def rel(path: Path) -> Path:
    """`path` relative to the checkout (the commands' working directory) when inside it: results record the paths
    they were made from, and the committed ones should not name one machine's checkout."""
    try:
        return path.relative_to(ROOT)
    except ValueError:
        return path
