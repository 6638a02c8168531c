#!/usr/bin/env bash
# The paper's Fig. 9b at the cpu scale: KINet with K in {3, 6, 12} keypoints beside the K = 9 rows
# (docs/results.md, "YCBObjs, the side camera at 96 px over three training seeds"), on the same
# data (`ycb_side96_cpu`, 3 objects), the same 8,000 steps and seed 0 (others via SEEDS), each
# scored on the same 256 test sequences and planned on the same 100 test episodes (seeds
# 50000-50099, T = 30, 64 x 3, the cost chosen on validation episodes, kinet_keypoints_distance).
# Two runs at once, one torch thread and one MPC worker each, on 2 cores. Measured on a 2-core
# Intel Xeon (docs/results.md, "Fig. 9b"): collection 13 min; K = 3, 6 and 12 all training at
# once (`... 3 6` and `... 12` started side by side) 53, 62 and 94 min; two at a time
# (`SEEDS="1 2" ... 6 12`) 42-44 min for K = 6 and 67 min for K = 12; K = 3 alone on one core
# 35 min; MPC 3-7 min per 100 episodes. Run from the repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_fig9b.sh                 # K = 3, 6 and 12, seed 0
#   bash docs/scripts/ycb_fig9b.sh 3 12            # only these K
#   SEEDS="1 2" bash docs/scripts/ycb_fig9b.sh 6   # other seeds (run names end _seed1, ...)
#
# Resumable: the collection, training and evaluation each resume where they stopped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
side96=(+exp=ycb_sideview +scale=cpu env.image_size=96)
mpc=(eval.episodes=100 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=1 eval.videos=0 "eval.num_objects=[]" "eval.methods=[kinet_keypoints_distance]")
if (($#)); then keypoints=("$@"); else keypoints=(3 6 12); fi
"$PYTHON" -m kinet_rl.collect "${side96[@]}"
mkdir -p runs
running=0
for k in "${keypoints[@]}"; do
  for s in ${SEEDS:-0}; do
    name=ycb_sideview96_k$k
    if ((s)); then name+=_seed$s; fi
    run=("${side96[@]}" exp_name=$name keypoints=$k seed=$s trainer.seed=$s)
    { "$PYTHON" -m kinet_rl.train "${run[@]}" trainer.steps=8000
      "$PYTHON" -m kinet_rl.evaluate "${run[@]}" "${mpc[@]}"
    } > "runs/$name.log" 2>&1 &
    running=$((running + 1))
    if ((running == 2)); then wait -n || true; running=$((running - 1)); fi  # its log says how it ended
  done
done
wait
