#!/usr/bin/env bash
# The paper's Fig. 9c at the cpu scale (docs/results.md, "YCBObjs: training on 1-5 objects"): YCB
# side camera at 96 px, KINet trained on episodes of 1-5 objects (`data.num_objects_range=[1,5]`,
# an object count per chunk of 50 episodes) instead of 3, the same 1,250 episodes, 8,000 steps and
# K = 9 as the 3-object rows, then planned on 20 test episodes per object count (1-5; seeds
# 50000-50019, T = 30, 64 x 3, the validated cost kinet_keypoints_distance), the budget and
# episodes of the 3-object model's object-count run. The training seeds given (default 0 and 1,
# the first session's) at once, one torch thread and one MPC worker each, on 2 cores. Run from the
# repository root with KINET_RL_YCB_DIR set:
#
#   bash docs/scripts/ycb_fig9c.sh      # seeds 0 and 1
#   bash docs/scripts/ycb_fig9c.sh 2    # the third seed
#
# Resumable: the collection, training and evaluation each resume where they stopped, and a seed
# whose evaluation finished is skipped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
data=(+exp=ycb_sideview +scale=cpu env.image_size=96 "data.num_objects_range=[1,5]"
  data.name=ycb_side96_1to5_cpu data.chunk_episodes=50)
counts=(eval.episodes=1 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=1 eval.videos=0 "eval.num_objects=[1,2,3,4,5]" eval.generalization_episodes=20
  "eval.methods=[kinet_keypoints_distance]")
"$PYTHON" -m kinet_rl.collect "${data[@]}"
mkdir -p runs
seeds=("$@")
[[ ${#seeds[@]} -gt 0 ]] || seeds=(0 1)
for seed in "${seeds[@]}"; do
  name=ycb_sideview96_1to5_seed$seed
  [[ -f runs/${name}_cpu/rearrangement/rearrangement.json ]] && continue
  run=("${data[@]}" exp_name=$name seed=$seed trainer.seed=$seed)
  { "$PYTHON" -m kinet_rl.train "${run[@]}" trainer.steps=8000
    "$PYTHON" -m kinet_rl.evaluate "${run[@]}" "${counts[@]}"
  } > "runs/ycb_fig9c_seed$seed.log" 2>&1 &
done
wait
