#!/usr/bin/env bash
# Train the TrueAdapt from-scratch experiments one after another (2 cores: one training at a time), each resumable,
# then evaluate each in PyBullet on the 1000 test trajectories and write its learning curve:
#   results/trueadapt_from_scratch/<experiment>_seed<S>.csv (+ .json, tools/lab/curve_summary.py) and
#   <experiment>_seed<S>_pybullet_metrics.json
# usage: tools/lab/trueadapt_scratch_queue.sh EXPERIMENT:SEED [EXPERIMENT:SEED ...]
# The task (on plate or in place) is read from the experiment's name; evaluation on datasets/iiwa7/trueadapt_<task>.
# Needs data/iiwa7/trueadapt_<task> (pathrl-dataset generate robot=iiwa7 dataset=trueadapt_<task>).
set -euo pipefail
cd "$(dirname "$0")/../.."
PY=.venv/bin/python
OUT=results/trueadapt_from_scratch
mkdir -p "$OUT"
for job in "$@"; do
  exp=${job%%:*}; seed=${job##*:}
  run=runs/$exp/seed$seed
  metrics=$OUT/${exp}_seed${seed}_pybullet_metrics.json
  task=on_plate; paper_steps=32e6
  [[ $exp == *in_place* ]] && { task=in_place; paper_steps=220e6; }
  [[ -f $metrics ]] && { echo "$job: done"; continue; }
  resume=false; [[ -d $run ]] && resume=true
  echo "$(date -u +%H:%M) $job: train (resume=$resume)"
  OMP_NUM_THREADS=1 .venv/bin/pathrl-train +experiment="$exp" seed="$seed" threads=1 resume=$resume
  $PY tools/lab/curve_summary.py "$run" "$OUT" --paper-steps $paper_steps --what "TrueAdapt from scratch: $exp seed $seed"
  echo "$(date -u +%H:%M) $job: evaluate"
  OMP_NUM_THREADS=1 $PY tools/trueadapt_eval.py --run "$run" --dataset datasets/iiwa7/trueadapt_$task \
    --episodes 1000 --backend pybullet --workers 1 --out "$run/eval_pybullet"
  cp "$run/eval_pybullet/metrics.json" "$metrics.tmp" && mv "$metrics.tmp" "$metrics"
done
