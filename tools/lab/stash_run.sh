#!/usr/bin/env bash
# Keep a long training resumable across machines: runs/ is not committed, so its latest checkpoint, config and
# training log are copied into results/checkpoints/<experiment>_seed<S>/ (committed), and back.
#   tools/lab/stash_run.sh save runs/<experiment>/seed<S>      # after stopping the training
#   tools/lab/stash_run.sh restore runs/<experiment>/seed<S>   # on a fresh clone, then pathrl-train ... resume=true
set -euo pipefail
cd "$(dirname "$0")/../.."
mode=${1:?save or restore}; run=${2:?run directory, e.g. runs/EXP/seed0}
exp=$(basename "$(dirname "$run")"); seed=$(basename "$run")
stash=results/checkpoints/${exp}_${seed}
case $mode in
  save)
    # the newest checkpoint that loads (pathrl.storage.checkpoints: the one resume=true would continue from)
    ckpt=$(.venv/bin/python -c "import sys; from pathlib import Path
from pathrl.storage.checkpoints import latest_valid_checkpoint
c = latest_valid_checkpoint(Path(sys.argv[1])); print(c or '')" "$run")
    [[ -n $ckpt ]] || { echo "stash_run: no checkpoint in $run" >&2; exit 2; }
    rm -rf "$stash.tmp" && mkdir -p "$stash.tmp"
    cp "$run/config.yaml" "$ckpt" "$stash.tmp/"
    for f in summary.json run.mcap; do [[ -f $run/$f ]] && cp "$run/$f" "$stash.tmp/"; done
    rm -rf "$stash" && mv "$stash.tmp" "$stash"
    echo "saved $run ($(basename "$ckpt")) -> $stash" ;;
  restore)
    [[ -d $stash ]] || { echo "stash_run: nothing stashed at $stash" >&2; exit 2; }
    [[ -e $run ]] && { echo "stash_run: $run exists; not overwritten" >&2; exit 2; }
    mkdir -p "$run" && cp "$stash"/* "$run/"
    echo "restored $stash -> $run" ;;
  *) echo "stash_run: mode must be save or restore, got $mode" >&2; exit 2 ;;
esac
