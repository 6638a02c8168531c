#!/usr/bin/env bash
# YCBObjs at the cpu scale, top camera (docs/results.md, "YCBObjs, unseen objects and the
# baselines"): the unseen-objects study (trained on 9 of the 12 YCB objects, scored and planned
# on the other 3 beside the seen ones) and the KINet-determ, Forw, ForwInv, VisIN and V-CDN rows
# on `ycb_top64_cpu` (the data of docs/scripts/ycb_cpu.sh's top-camera KINet run). KINet,
# KINet-determ and V-CDN train 8,000 steps as that run did; the other baselines the cpu scale's
# 10,000. MPC: the same 100 test episodes (T = 30) and budget (64 x 3) as docs/scripts/ycb_cpu.sh.
# Three chains at once, one torch thread each, on 2 cores. Run from the repository root with
# KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_unseen_baselines.sh
#
# Resumable: collection, training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
top=(+scale=cpu env.image_size=64)  # the top camera's run: the YCB size before the image-size study
mpc=(eval.episodes=100 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=2)
unseen() {
  "$PYTHON" -m kinet_rl.train +exp=ycb_topview_unseen trainer.steps=8000
  local planned=("${mpc[@]}" eval.videos=1 "eval.methods=[kinet_keypoints_l2,oracle]"
    "eval.num_objects=[]")
  "$PYTHON" -m kinet_rl.evaluate +exp=ycb_topview_unseen "${planned[@]}"  # the 9 seen objects
  "$PYTHON" -m kinet_rl.evaluate +exp=ycb_topview_unseen "${planned[@]}" \
    "env.ycb_objects=[004_sugar_box,007_tuna_fish_can,025_mug]" \
    checkpoint=runs/ycb_topview_unseen_cpu/kinet.pt hydra.run.dir=runs/ycb_topview_unseen_cpu_heldout
}
baselines() {
  local model
  for model in forw forwinv visin; do
    "$PYTHON" -m kinet_rl.train +exp=ycb_topview_$model "${top[@]}"
  done
  "$PYTHON" -m kinet_rl.train +exp=ycb_topview_vcdn "${top[@]}" trainer.steps=8000
  for model in forw forwinv vcdn; do
    "$PYTHON" -m kinet_rl.evaluate +exp=ycb_topview_$model "${top[@]}" "${mpc[@]}" eval.videos=0 \
      "eval.methods=[model_mpc]" "eval.num_objects=[]"
  done
}
mkdir -p runs
"$PYTHON" -m kinet_rl.train +exp=ycb_topview_determ "${top[@]}" trainer.steps=8000 \
  > runs/ycb_determ.log 2>&1 &
unseen > runs/ycb_unseen.log 2>&1 &
baselines > runs/ycb_baselines.log 2>&1 &
wait
