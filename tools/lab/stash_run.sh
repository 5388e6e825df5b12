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
    last=$(ls "$run"/model_*.pt | sed 's/.*model_\([0-9]*\)\.pt/\1/' | sort -n | tail -1)
    [[ -n $last ]] || { echo "stash_run: no checkpoint in $run" >&2; exit 2; }
    mkdir -p "$stash.tmp"
    cp "$run/config.yaml" "$run/model_$last.pt" "$stash.tmp/"
    for f in summary.json run.mcap; do [[ -f $run/$f ]] && cp "$run/$f" "$stash.tmp/"; done
    rm -rf "$stash" && mv "$stash.tmp" "$stash"
    echo "saved $run (model_$last.pt) -> $stash" ;;
  restore)
    [[ -d $stash ]] || { echo "stash_run: nothing stashed at $stash" >&2; exit 2; }
    [[ -e $run ]] && { echo "stash_run: $run exists; not overwritten" >&2; exit 2; }
    mkdir -p "$run" && cp "$stash"/* "$run/"
    echo "restored $stash -> $run" ;;
  *) echo "stash_run: mode must be save or restore, got $mode" >&2; exit 2 ;;
esac
