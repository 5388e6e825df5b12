#!/usr/bin/env bash
# TD3 + PER on the calibrated controller model (controller.model=abb), seeds one after another (one core: one
# training at a time), each resumable, then each evaluated beside MPGD and ILC on the nine Table II rows:
#   runs/industrial_td3_abb/seed<S>           the run (model_<K>.pt every 500 iterations; resume=true continues)
#   results/industrial_abb_table2_seed<S>.md  tools/lab/industrial_abb.py table2 (executions per row, a1-a3)
# usage: tools/lab/industrial_abb_seeds.sh [SEED ...]   (default 0 1 2 3 4; ~16 min of one core per seed)
# The recipe (docs/industrial.md, "TD3 + PER on the calibrated model: why it collapsed"): the paper's clip and
# reward weights; exploration noise correlated along the path, the critic's action input x 10, actor lr 3e-5.
set -euo pipefail
cd "$(dirname "$0")/../.."
ITERATIONS=${ITERATIONS:-5000}
RECIPE=(controller.model=abb rl.action_clip=2.0 rl.w_ori=0.5 rl.success_decay=0.8 rl.expl_smooth=3
        rl.critic_action_gain=10 rl.lr_actor=3e-5 rl.checkpoint_every=500 rl.log_every=100)
seeds=("$@"); [[ ${#seeds[@]} -gt 0 ]] || seeds=(0 1 2 3 4)
for seed in "${seeds[@]}"; do
  run=runs/industrial_td3_abb/seed$seed
  out=results/industrial_abb_table2_seed$seed.md
  [[ -f $out ]] && { echo "seed $seed: done ($out)"; continue; }
  resume=false; [[ -d $run ]] && resume=true
  echo "$(date -u +%H:%M) seed $seed: train to $ITERATIONS iterations (resume=$resume)"
  OMP_NUM_THREADS=1 .venv/bin/pathrl-industrial train "${RECIPE[@]}" rl.iterations="$ITERATIONS" rl.seed="$seed" \
    run_dir="$run" resume=$resume
  echo "$(date -u +%H:%M) seed $seed: evaluate"
  OMP_NUM_THREADS=1 .venv/bin/python tools/lab/industrial_abb.py table2 "$run" "$out"
done
