#!/usr/bin/env bash
# YCBObjs at the cpu scale, side camera at 96 px (docs/results.md, "The ablations, V-CDN, IN-full
# and the baselines' seeds on the side camera at 96 px"): the Table I rows that
# ycb_side96_seeds_baselines.sh left out, on the same data (`ycb_side96_cpu`, 3 objects) and
# planned with the same budget on the same 100 test episodes (seeds 50000-50099, T = 30, 64 x 3):
# KINet-no-ctr and V-CDN (8,000 steps, as KINet; V-CDN's first half trains its
# perception), IN and IN-full on ground-truth state (the cpu scale's 10,000), then training seeds
# 1 and 2 of every baseline (Forw, ForwInv, VisIN, IN, IN-full; 10,000 steps, as their seed 0)
# and of KINet-no-ctr (8,000 steps, as its seed 0), cheapest first; then KINet-determ's three seeds
# (8,000 steps) and V-CDN's seeds 1 and 2.
# Two or three jobs at once, one torch thread and one MPC worker each, on 2 cores. Run from the
# repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_side96_ablations.sh        # every part
#   bash docs/scripts/ycb_side96_ablations.sh rows   # the new rows only (seed 0); `seeds`: the
#                                                    # baselines' seeds 1-2; `determ`: KINet-determ's
#                                                    # 3 seeds and V-CDN's seeds 1-2
#
# Resumable: training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
source "$(dirname "$0")/ycb_rows.sh"
row() { ycb_row side 96 "$@"; }  # model, planning method, seed, extra training overrides
rows() {
  {
    row vcdn model_mpc 0 trainer.steps=8000
    row in model_mpc 0
    row in_full model_mpc 0
    row forwinv model_mpc 2
  } > runs/ycb_side96_ablations_a.log 2>&1 &
  {
    row no_ctr kinet_keypoints_distance 0 trainer.steps=8000
    row forwinv model_mpc 1
  } > runs/ycb_side96_ablations_b.log 2>&1 &
  wait
}
seeds() {  # forwinv's seeds 1-2 ran in rows(); one chain per seed
  for seed in 1 2; do
    {
      for model in in in_full visin forw; do row $model model_mpc $seed; done
      row no_ctr kinet_keypoints_distance $seed trainer.steps=8000
    } > runs/ycb_side96_seeds_$seed.log 2>&1 &
  done
  wait
}
determ() {  # KINet-determ's three seeds at once (3 jobs on 2 cores), then V-CDN's seeds 1-2
  for seed in 0 1 2; do
    row determ kinet_keypoints_distance $seed trainer.steps=8000 \
      > runs/ycb_side96_determ_$seed.log 2>&1 &
  done
  wait
  for seed in 1 2; do
    row vcdn model_mpc $seed trainer.steps=8000 > runs/ycb_side96_vcdn_$seed.log 2>&1 &
  done
  wait
}
mkdir -p runs
# The data first, once (both chains read it; skipped when complete):
"$PYTHON" -m kinet_rl.collect +exp=ycb_sideview +scale=cpu env.image_size=96
case "${1:-all}" in
  rows) rows ;;
  seeds) seeds ;;
  determ) determ ;;
  all) rows; seeds; determ ;;
  *) echo "usage: $0 [rows|seeds|determ|all]" >&2; exit 2 ;;
esac
