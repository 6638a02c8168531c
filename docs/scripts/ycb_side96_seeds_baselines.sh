#!/usr/bin/env bash
# YCBObjs at the cpu scale, side camera at 96 px (docs/results.md, "YCBObjs, the side camera at
# 96 px over three training seeds, and its baselines"): KINet's training seeds 1 and 2 beside docs/scripts/
# ycb_cpu.sh's seed 0 (8,000 steps each, as that run), planned with the YCB experiments'
# validated cost (kinet_keypoints_distance) on the same 100 test episodes (T = 30, 64 x 3), and
# the Forw, ForwInv and VisIN rows on the same data (`ycb_side96_cpu`, the cpu scale's 10,000
# steps), planned with the same budget. Two chains at once, one torch thread and one MPC worker
# each, on 2 cores. Run from the repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_side96_seeds_baselines.sh
#
# Resumable: training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
side96=(+exp=ycb_sideview +scale=cpu env.image_size=96)
mpc=(eval.episodes=100 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=1 eval.videos=0 "eval.num_objects=[]")
kinet_seed() {  # seed: trained and planned
  local run=("${side96[@]}" exp_name=ycb_sideview96_seed$1 seed=$1 trainer.seed=$1)
  "$PYTHON" -m kinet_rl.train "${run[@]}" trainer.steps=8000
  "$PYTHON" -m kinet_rl.evaluate "${run[@]}" "${mpc[@]}" "eval.methods=[kinet_keypoints_distance]"
}
baseline() {  # model: trained and planned on the same data
  local run=(+exp=ycb_sideview_$1 +scale=cpu env.image_size=96 exp_name=ycb_sideview96_$1)
  "$PYTHON" -m kinet_rl.train "${run[@]}"
  "$PYTHON" -m kinet_rl.evaluate "${run[@]}" "${mpc[@]}" "eval.methods=[model_mpc]"
}
mkdir -p runs
{ kinet_seed 1; baseline forw; baseline visin; } > runs/ycb_side96_chain_a.log 2>&1 &
{ kinet_seed 2; baseline forwinv; } > runs/ycb_side96_chain_b.log 2>&1 &
wait
