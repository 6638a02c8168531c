#!/usr/bin/env bash
# The side-camera ablation rows of Table I at the cpu scale that earlier sessions left out:
# KINet-determ (seeds 0, 1, 2) and KINet-no-ctr (seed 2). Two chains of two rows, one torch thread
# each, so the two cores train two rows at once. Run from the repository root after collecting
# `data/tables_cpu_side` (the tables collect it themselves when it is missing, but two chains must
# not collect it at once):
#
#   python -m kinet_rl.collect +exp=blocks_sideview data.name=tables_cpu_side data.num_episodes=1250 \
#       data.num_workers=2 data.chunk_episodes=25 data.generalization=null
#   bash docs/scripts/side_ablations_cpu.sh
#
# Each row is trained and scored (Table I's forward errors) by `python -m kinet_rl.tables`; the MPC
# stage is cut to 4 episodes (not reported: the MPC tables are on the top camera). Resumable.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
common=(tables=cpu 'tables.generalization_models=[]' 'tables.mpc_budgets=null'
  '+tables.mpc_budgets={64x3:{num_candidates:64,optim_steps:3,top_k:8}}' tables.eval.episodes=4
  'tables.cameras=[side]' tables.mpc_camera=side)
source "$(dirname "$0")/table_rows.sh"
rows runs/side_ablations_a kinet_determ 0 kinet_determ 1 > runs/side_ablations_a.log 2>&1 &
rows runs/side_ablations_b kinet_determ 2 kinet_no_ctr 2 > runs/side_ablations_b.log 2>&1 &
wait
