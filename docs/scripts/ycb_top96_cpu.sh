#!/usr/bin/env bash
# YCBObjs' Table I on the top camera at 96 px (24x24 heatmaps), cpu scale, 3 training seeds per
# row: the top camera at 64 px sat on its detector floor (docs/results.md, "The top camera (KINet
# and IN, 64 px)"), and 96 px fixed the side camera's detector. Collects `ycb_top96_cpu`, then
# trains and plans each row with `ycb_row` (docs/scripts/ycb_rows.sh: the same data, 256 test
# sequences and 100 test episodes for every row): KINet, KINet-determ, KINet-no-ctr and V-CDN
# for 8,000 steps (as on the side camera at 96 px), the others for the cpu scale's 10,000; KINet
# and its ablations plan with `kinet_keypoints_distance` (the YCB experiments' validated cost),
# the others with `model_mpc`. Run from the repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_top96_cpu.sh
#
# Two chains, one torch thread and one MPC worker each (2 cores; three jobs at once measured no
# faster on the side camera), take the rows below in order, each the next row no chain has taken.
# The whole table is ~15 core-hours (the side camera's row times: ~80 min per KINet-sized row),
# more than one session: stop it at any time (Ctrl-C, or the session ends) and run it again, one
# copy at a time: finished rows are skipped and a stopped row resumes where it stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
source "$(dirname "$0")/ycb_rows.sh"
keypoints=kinet_keypoints_distance
long=trainer.steps=8000
rows=()  # <model> <method> <seed> [training overrides]
for seed in 0 1 2; do rows+=("kinet $keypoints $seed $long"); done
for seed in 0 1 2; do rows+=("in model_mpc $seed" "in_full model_mpc $seed"); done
# the baselines before the ablations: a session finishes whole rows of the cheap ones
for seed in 0 1 2; do
  rows+=("forw model_mpc $seed" "forwinv model_mpc $seed" "visin model_mpc $seed")
done
for seed in 0 1 2; do rows+=("vcdn model_mpc $seed $long"); done
for model in determ no_ctr; do
  for seed in 0 1 2; do rows+=("$model $keypoints $seed $long"); done
done
"$PYTHON" -m kinet_rl.collect +exp=ycb_topview +scale=cpu env.image_size=96
claims=runs/ycb_top96_claims  # a row is taken by the chain that creates its folder here
rm -rf "$claims"
mkdir -p "$claims"
chain() {
  local i
  for i in "${!rows[@]}"; do
    if mkdir "$claims/$i" 2> /dev/null; then
      # shellcheck disable=SC2086  # a row is words
      ycb_row top 96 ${rows[i]}
    fi
  done
}
for c in 0 1; do chain > "runs/ycb_top96_chain_$c.log" 2>&1 & done
wait
