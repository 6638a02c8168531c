#!/usr/bin/env bash
# The YCB image-size study's third size: KINet on the side camera at 128 px (32x32 heatmaps),
# cpu scale, beside the 64 and 96 px runs of docs/results.md ("The side camera at 96 px (the
# image-size study: 64, 96 and 128 px)"). Collects `ycb_side128_cpu` (the 96 px copy's 1,250
# episodes, positions and pushes identical to the byte, rendered at 128 px), then trains KINet
# seed 0 for 8,000 steps as at 96 px and plans it on the YCB MPC protocol's 100 test episodes
# with `kinet_keypoints_distance` (`ycb_row`, docs/scripts/ycb_rows.sh). Run from the repository
# root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_side128_cpu.sh
#
# ~4 core-hours on a 2-core machine (measured: collection 45 min with 2 workers, training 2 h 29
# min on one core beside another job, MPC 8 min with one worker): stop it at any time and run it
# again; collection, training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
source "$(dirname "$0")/ycb_rows.sh"
"$PYTHON" -m kinet_rl.collect +exp=ycb_sideview +scale=cpu env.image_size=128
ycb_row side 128 kinet kinet_keypoints_distance 0 trainer.steps=8000
