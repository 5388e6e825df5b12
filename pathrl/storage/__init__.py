"""Files a run leaves behind: atomic writes and verified checkpoints."""

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

__all__ = [
    "CHECKPOINT_RE", "CheckpointError", "atomic_write", "checkpoint_iteration", "clean_leftovers", "content_digest",
    "latest_checkpoint", "latest_valid_checkpoint", "load_checkpoint", "run_checkpoints", "save_checkpoint",
    "write_json_atomic",
]
