#!/usr/bin/env bash
# YCBObjs at the cpu scale beyond the first side-camera run (docs/results.md, "YCBObjs at the cpu
# scale"): the top camera at 64 px (KINet and IN) and the side camera at 96 px (KINet: the
# image-size study against the 64 px run), each trained and scored by `python -m
# kinet_rl.train`, then planned with the same budget on the same 100 test episodes (T = 30) by
# `kinet_rl.evaluate`.
# 8,000 training steps for KINet (the cpu scale's 10,000 did not fit the session that ran
# this; KINet's training has no schedule tied to the step count, so a run stopped at 8,000 is
# this run); IN the cpu scale's 10,000. Two chains at once, one torch thread each, on 2 cores.
# Run from the repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_cpu.sh
#
# Resumable: collection, training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
mpc=(eval.episodes=100 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=2)
top() {
  local top=(+scale=cpu env.image_size=64)  # the YCB size before the image-size study
  "$PYTHON" -m kinet_rl.train +exp=ycb_topview "${top[@]}" trainer.steps=8000
  "$PYTHON" -m kinet_rl.train +exp=ycb_topview_in "${top[@]}"  # 10,000 steps (~5 min)
  "$PYTHON" -m kinet_rl.evaluate +exp=ycb_topview "${top[@]}" "${mpc[@]}" eval.videos=1 \
    "eval.methods=[kinet_keypoints_l2,random,oracle]" "eval.num_objects=[1,2,3,4,5]" \
    eval.generalization_episodes=10
  "$PYTHON" -m kinet_rl.evaluate +exp=ycb_topview_in "${top[@]}" "${mpc[@]}" eval.videos=0 \
    "eval.methods=[model_mpc]" "eval.num_objects=[]"
}
side96() {
  local side96=(+exp=ycb_sideview +scale=cpu env.image_size=96 exp_name=ycb_sideview96)
  "$PYTHON" -m kinet_rl.train "${side96[@]}" trainer.steps=8000
  "$PYTHON" -m kinet_rl.evaluate "${side96[@]}" "${mpc[@]}" eval.videos=1 \
    "eval.methods=[kinet_keypoints_l2]" "eval.num_objects=[]"
}
mkdir -p runs
top > runs/ycb_top_cpu.log 2>&1 &
side96 > runs/ycb_side96_cpu.log 2>&1 &
wait
