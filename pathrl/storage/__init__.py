"""Files a run leaves behind: atomic writes, verified checkpoints, output destinations checked before the work."""

from pathrl.storage.atomic import atomic_write, write_json_atomic
from pathrl.storage.checkpoints import (
    CHECKPOINT_RE,
    CheckpointError,
    checkpoint_iteration,
    clean_leftovers,
    content_digest,
    latest_checkpoint,
    latest_valid_checkpoint,
    load_checkpoint,
    run_checkpoints,
    save_checkpoint,
)
from pathrl.storage.destination import (
    DestinationError,
    check_dir_destination,
    check_file_destination,
    inside_models,
    models_dirs,
)

__all__ = [
    "CHECKPOINT_RE", "CheckpointError", "DestinationError", "atomic_write", "check_dir_destination",
    "check_file_destination", "checkpoint_iteration", "clean_leftovers", "content_digest", "inside_models",
    "latest_checkpoint", "latest_valid_checkpoint", "load_checkpoint", "models_dirs", "run_checkpoints",
    "save_checkpoint", "write_json_atomic",
]
