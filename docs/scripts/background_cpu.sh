#!/usr/bin/env bash
# The background study (the paper's Fig. 4b) at the cpu scale, trained on random table textures:
# the cpu-scale KINet row (+exp=blocks_topview with conf/tables/cpu.yaml's overrides, seed 0) on
# 1,250 episodes with a random texture and colour per episode, then MPC (index-matched keypoint
# L2, 64 x 3) on 20 test episodes with the fixed background and 20 with random textures (the same
# scenes as Table II's background cell). Run from the repository root:
#
#   bash docs/scripts/background_cpu.sh
#
# Resumable: the training resumes from its checkpoint, a finished step is skipped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
RUN=runs/cpu_random_background
CPU_SCALE=(data.num_episodes=1250 data.num_workers=2 data.chunk_episodes=25
  data.generalization=null trainer.steps=10000 trainer.batch_size=32 trainer.eval_every=1000
  trainer.checkpoint_every=1000 trainer.log_every=100 report.rearrangement_episodes=0
  estimate=false)
if [[ ! -f $RUN/results.json ]]; then
  start=$SECONDS
  "$PYTHON" -m kinet_rl.train +exp=blocks_topview "${CPU_SCALE[@]}" env.background=random \
    data.name=tables_cpu_top_random exp_name=blocks_topview_random_background hydra.run.dir=$RUN
  echo "train: $((SECONDS - start)) s" >> $RUN/wall_time.txt
fi
if [[ ! -f $RUN/rearrangement/rearrangement.json ]]; then
  start=$SECONDS
  "$PYTHON" -m kinet_rl.evaluate +exp=blocks_topview checkpoint=$RUN/kinet.pt \
    'eval.methods=[kinet_keypoints_l2]' eval.episodes=20 eval.generalization_episodes=20 \
    'eval.num_objects=[]' 'eval.backgrounds=[random]' eval.workers=2 eval.videos=0 \
    hydra.run.dir=$RUN
  echo "evaluate: $((SECONDS - start)) s" >> $RUN/wall_time.txt
fi
