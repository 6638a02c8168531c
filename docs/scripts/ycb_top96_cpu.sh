#!/usr/bin/env bash
# YCBObjs' Table I on the top camera at 96 px (24x24 heatmaps), cpu scale, 3 training seeds per
# row: the top camera at 64 px sat on its detector floor (docs/results.md, "The top camera (KINet
# and IN, 64 px)"), and 96 px fixed the side camera's detector. Collects `ycb_top96_cpu`, then
# trains and plans each row with `ycb_row` (docs/scripts/ycb_rows.sh: the same data, 256 test
# sequences and 100 test episodes for every row): KINet, KINet-determ, KINet-no-ctr and V-CDN
# for 8,000 steps (as on the side camera at 96 px), the others for the cpu scale's 10,000; KINet
# and its ablations plan with `kinet_keypoints_distance` (the YCB experiments' validated cost),
# the others with `model_mpc`. One torch thread and one MPC worker per job, on 2 cores. Run from
# the repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_top96_cpu.sh [part]
#
# Parts, each estimated at about a session on 2 cores (not measured: from the side camera's 77 min
# per KINet seed at 96 px with two jobs at once): `first` (KINet's 3 seeds, one job each, then
# IN's 3 seeds after KINet's seed 0 and IN-full's after seed 1), `determ` and `no_ctr` (3 seeds
# each, one job per seed), `baselines` (Forw, ForwInv, VisIN and V-CDN, one chain per seed).
#
# Resumable: the collection, training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
source "$(dirname "$0")/ycb_rows.sh"
row() { ycb_row top 96 "$@"; }
keypoints=kinet_keypoints_distance
part=${1:-first}
case "$part" in
  first | determ | no_ctr | baselines) ;;
  *) echo "usage: $0 [first|determ|no_ctr|baselines]" >&2; exit 2 ;;
esac
"$PYTHON" -m kinet_rl.collect +exp=ycb_topview +scale=cpu env.image_size=96
mkdir -p runs
case "$part" in
  first)
    {
      row kinet $keypoints 0 trainer.steps=8000
      for seed in 0 1 2; do row in model_mpc $seed; done
    } > runs/ycb_top96_first_0.log 2>&1 &
    {
      row kinet $keypoints 1 trainer.steps=8000
      for seed in 0 1 2; do row in_full model_mpc $seed; done
    } > runs/ycb_top96_first_1.log 2>&1 &
    row kinet $keypoints 2 trainer.steps=8000 > runs/ycb_top96_first_2.log 2>&1 &
    ;;
  determ | no_ctr)
    for seed in 0 1 2; do
      row "$part" $keypoints $seed trainer.steps=8000 > "runs/ycb_top96_${part}_$seed.log" 2>&1 &
    done
    ;;
  baselines)
    for seed in 0 1 2; do
      {
        for model in visin forw forwinv; do row $model model_mpc $seed; done
        row vcdn model_mpc $seed trainer.steps=8000
      } > runs/ycb_top96_baselines_$seed.log 2>&1 &
    done
    ;;
esac
wait
