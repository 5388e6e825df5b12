#!/usr/bin/env bash
# Table IV ablations of TD3 + PER on the calibrated controller model (controller.model=abb): the recipe of
# tools/lab/industrial_abb_seeds.sh with PER off (rl.per_alpha=0) or one feature group zeroed (rl.ablate), trained one
# after another (one core: one training at a time), each resumable:
#   runs/industrial_td3_abb_<variant>/seed<S>   (model_<K>.pt every 500 iterations; resume=true continues)
# usage: tools/lab/industrial_abb_ablations.sh SEED [SEED ...]   (~6 min of one core per variant and seed)
# then: pathrl-industrial table4 controller.model=abb table4_runs=[...] (docs/industrial.md shows the command)
set -euo pipefail
cd "$(dirname "$0")/../.."
ITERATIONS=${ITERATIONS:-5000}
RECIPE=(controller.model=abb rl.action_clip=2.0 rl.w_ori=0.5 rl.success_decay=0.8 rl.expl_smooth=3
        rl.critic_action_gain=10 rl.lr_actor=3e-5 rl.checkpoint_every=500 rl.log_every=100)
declare -A VARIANTS=([no_per]="rl.per_alpha=0" [no_ptarget]="rl.ablate=[p_target]" [no_q_fjac]="rl.ablate=[q_fjac]"
                     [no_e]="rl.ablate=[e]")
[[ $# -gt 0 ]] || { echo "usage: $0 SEED [SEED ...]" >&2; exit 2; }
for seed in "$@"; do
  for variant in no_per no_ptarget no_q_fjac no_e; do
    run=runs/industrial_td3_abb_$variant/seed$seed
    [[ -f $run/model_$ITERATIONS.pt ]] && { echo "$variant seed $seed: done"; continue; }
    resume=false; [[ -d $run ]] && resume=true
    echo "$(date -u +%H:%M) $variant seed $seed: train to $ITERATIONS iterations (resume=$resume)"
    OMP_NUM_THREADS=1 .venv/bin/pathrl-industrial train "${RECIPE[@]}" "${VARIANTS[$variant]}" \
      rl.iterations="$ITERATIONS" rl.seed="$seed" run_dir="$run" resume=$resume
  done
done
