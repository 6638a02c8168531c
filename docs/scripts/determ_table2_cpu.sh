#!/usr/bin/env bash
# Table II's second column (the paper's KINet-determ) at the cpu scale: the top-camera KINet-determ
# row of Table I (seed 0, trained and scored by `python -m kinet_rl.tables`, which collects
# `tables_cpu_top` when it is missing; its MPC stage cut to 4 episodes), then the cpu-scale KINet's
# Table II command on its checkpoint (MPC on index-matched keypoint L2, 64 x 3, T = 40, 20 test
# episodes per cell, 1-5 objects x train/gen geometry, and the random-texture cell). Run from the
# repository root:
#
#   bash docs/scripts/determ_table2_cpu.sh
#
# Resumable: the row resumes from its checkpoint, the evaluation from its stored episodes.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
RUN=runs/determ_top
common=(tables=cpu 'tables.generalization_models=[]' 'tables.mpc_budgets=null'
  '+tables.mpc_budgets={64x3:{num_candidates:64,optim_steps:3,top_k:8}}' tables.eval.episodes=4
  'tables.cameras=[top]')
source "$(dirname "$0")/table_rows.sh"
mkdir -p $RUN
start=$SECONDS
rows $RUN kinet_determ 0
echo "row: $((SECONDS - start)) s" >> $RUN/wall_time.txt
start=$SECONDS
"$PYTHON" -m kinet_rl.evaluate +exp=blocks_topview_determ \
  checkpoint=$RUN/blocks_topview_determ/kinet.pt 'eval.methods=[kinet_keypoints_l2]' \
  eval.episodes=2 eval.generalization_episodes=20 'eval.num_objects=[1,2,3,4,5]' \
  'eval.geometries=[train,gen]' 'eval.backgrounds=[random]' eval.workers=1 eval.videos=0 \
  hydra.run.dir=runs/table2_determ
echo "table2: $((SECONDS - start)) s" >> $RUN/wall_time.txt
