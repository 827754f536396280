#!/usr/bin/env bash
# One DAgger round for C-VPT tiny on a CPU (docs/dagger.md): roll out the last round's learner
# with the scripted expert labelling every state, then train on the expert data plus every
# round's labels from the last round's weights, then score the new weights in both games.
#
#   bash scripts/dagger_round.sh ROUND LEARNER_CKPT BETA [EPISODES]
#
# ROUND 1 starts from plain BC (zoo fit --config configs/cvpt_tiny_cpu.yaml). Each stage is
# skipped when its output exists (rollouts resume shard by shard), so a killed round reruns.
# Environment: EXPERT_DATA (default data/crafterplay_scripted_early), DAGGER_DIR (data/dagger),
# RUNS (runs/cvpt_tiny_cpu_dagger), MIX (step), EXPERT_WEIGHT (1), ROUND_WEIGHT (1, each round),
# FIT_ARGS (extra zoo fit arguments), EVAL_EPISODES (100).
set -euo pipefail

round=${1:?round number}
learner=${2:?learner checkpoint}
beta=${3:?beta}
episodes=${4:-256}
expert_data=${EXPERT_DATA:-data/crafterplay_scripted_early}
dagger_dir=${DAGGER_DIR:-data/dagger}
runs=${RUNS:-runs/cvpt_tiny_cpu_dagger}
zoo=${ZOO:-.venv/bin/zoo}
log() { echo "[$(date -u +%H:%M:%S)] round $round: $*"; }

log "rollouts of $learner (beta $beta, ${MIX:-step} mixing, $episodes episodes)"
start=$(date +%s)
"$zoo" data dagger --checkpoint "$learner" --round "$round" --beta "$beta" --mix "${MIX:-step}" \
    --episodes "$episodes" --seed $((100 + round)) --max-steps 1000 --env craftax \
    --episodes-per-shard 16 --num-envs 16 --workers 2 --out "$dagger_dir/r$round" --no-progress
log "rollouts took $(( $(date +%s) - start )) s"

sources="[{root: $expert_data, weight: ${EXPERT_WEIGHT:-1}}"
for r in $(seq 1 "$round"); do
    sources+=", {root: $dagger_dir/r$r, weight: ${ROUND_WEIGHT:-1}}"
done
sources+="]"
out="$runs/r$round"
if ! ls "$out"/*/checkpoints/last.ckpt >/dev/null 2>&1; then
    log "training on $sources"
    start=$(date +%s)
    # shellcheck disable=SC2086
    "$zoo" fit --config configs/cvpt_tiny_cpu_dagger.yaml \
        --model.init_args.init_weights="$learner" --data.init_args.sources="$sources" \
        --trainer.default_root_dir "$out" ${FIT_ARGS:-}
    log "training took $(( $(date +%s) - start )) s"
fi
# the round's weights are the last ones, at the end of the short cosine: the 8-batch
# validation loss moves less between checkpoints than its own noise
weights=$(ls -t "$out"/*/checkpoints/last.ckpt | head -1)
log "weights $weights"
for env in craftax crafter; do
    if [ ! -f "$out/eval-$env/report.json" ]; then
        "$zoo" eval --checkpoint "$weights" --env "$env" --episodes "${EVAL_EPISODES:-100}" \
            --num-envs 20 --out "$out/eval-$env" --no-gif
    fi
done
log "done: $weights"
