#!/usr/bin/env bash
# The paper's MPC protocol on a lent GPU machine, as one script (docs/results.md, "The paper's
# protocol: 1,000 test episodes"): the shipped cpu-scale KINet (`pretrained:blocks_topview`)
# planned on index-matched keypoint L2, with the oracle and random pushes on the same episodes
# (test seeds 50000-50999, T = 40, 3 blocks, top camera), at both budgets of the MPC tables
# (64 x 3 and 256 x 5). Each budget's evaluation lands in $OUT/<budget>/ (results JSON, report,
# curves) with its wall time in $OUT/wall_times.txt; an interrupted run resumes from its stored
# episodes. Run from the repository root:
#
#   OUT=/tmp/out bash docs/scripts/protocol1000_gpu.sh              # 1,000 episodes, both budgets
#   EPISODES=4 WORKERS=1 bash docs/scripts/protocol1000_gpu.sh 64x3  # a quick check on a CPU
#
# WORKERS (default: every core) episode processes, each running BATCH episodes (default 8) in
# lockstep with one batched planner call per push: batched episodes push exactly as they do one
# at a time (docs/planning.md), and on a GPU the batch is what fills the device.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
OUT="${OUT:-runs/protocol1000_gpu}"
EPISODES="${EPISODES:-1000}"
WORKERS="${WORKERS:-$(nproc)}"
BATCH="${BATCH:-8}"
budgets=("$@")
[[ ${#budgets[@]} -gt 0 ]] || budgets=(64x3 256x5)
mkdir -p "$OUT"
for budget in "${budgets[@]}"; do
  case $budget in
    64x3) planner=() ;;
    256x5) planner=(eval.planner.num_candidates=256 eval.planner.optim_steps=5 eval.planner.top_k=16) ;;
    *) echo "unknown budget '$budget': use 64x3 or 256x5" >&2; exit 2 ;;
  esac
  start=$SECONDS
  "$PYTHON" -m kinet_rl.evaluate +exp=blocks_topview checkpoint=pretrained:blocks_topview \
    eval.episodes="$EPISODES" 'eval.methods=[kinet_keypoints_l2,oracle,random]' \
    'eval.num_objects=[]' 'eval.backgrounds=[]' eval.videos=0 eval.workers="$WORKERS" \
    eval.batch_episodes="$BATCH" "${planner[@]}" hydra.run.dir="$OUT/$budget"
  echo "$budget: $((SECONDS - start)) s, $EPISODES episodes x 3 methods, $WORKERS workers x $BATCH" \
    >> "$OUT/wall_times.txt"
done
