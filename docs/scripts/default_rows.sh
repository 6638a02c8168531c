#!/usr/bin/env bash
# The planning measurements of the *default* experiment (docs/results.md, "The default model under
# the MPC protocol"): the default KINet and, on the same data with the same steps, the IN, Forw and
# ForwInv baselines; the headline MPC table
# at two budgets (100 test episodes), Table II with the background study (20 test episodes per
# cell) and the random-texture model's evaluation. Run from the repository root:
#
#   bash docs/scripts/default_rows.sh
#   bash docs/scripts/default_rows.sh costs   # only the default KINet and its cost groups (the end)
#
# Everything lands in runs/default_rows (models), runs/mpc_default (MPC JSON per row),
# runs/table2_default and runs/background_default (evaluations). Every step is skipped when its
# output exists, so an interrupted run resumes.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
R=runs/default_rows
# The default experiment's data and training budget, for the baselines' experiments too.
DEFAULT_SCALE=(data.name=blocks_top64 data.num_episodes=100 data.num_workers=2
  data.chunk_episodes=16 data.generalization=null trainer.steps=1500 trainer.batch_size=32
  trainer.log_every=25 trainer.eval_every=250 trainer.checkpoint_every=250)
BUDGET_256X5='{"return_best": true, "num_candidates": 256, "optim_steps": 5, "top_k": 16}'
NO_MPC=(report.rearrangement_episodes=0 estimate=false)
TABLE2=('eval.methods=[kinet_keypoints_l2]' eval.episodes=2 eval.generalization_episodes=20
  'eval.num_objects=[1,2,3,4,5]' 'eval.geometries=[train,gen]' 'eval.backgrounds=[random]'
  eval.workers=2 eval.videos=0)

timed() {  # timed <name> <command...>: runs the command unless runs/default_times/<name> exists
  local stamp=runs/default_times/$1
  shift
  [[ -f $stamp ]] && return
  local start=$SECONDS
  "$@"
  mkdir -p runs/default_times
  echo "$((SECONDS - start)) s: $*" > "$stamp"
}

timed kinet "$PYTHON" -m kinet_rl.train "${NO_MPC[@]}" hydra.run.dir=$R/blocks_topview
if [[ ${1:-all} != costs ]]; then  # the baselines, the headline table, Table II, background
  for model in in forw forwinv; do
    timed $model "$PYTHON" -m kinet_rl.train +exp=blocks_topview_$model "${DEFAULT_SCALE[@]}" \
      "${NO_MPC[@]}" hydra.run.dir=$R/blocks_topview_$model
  done
  # The headline MPC table at two budgets: KINet's chosen cost, IN, Forw, ForwInv (random pushes and
  # the oracle need no model: their rows are the cpu-scale ones, on the same test episodes).
  "$PYTHON" docs/scripts/mpc_cpu.py test --runs $R --out runs/mpc_default/test_64x3 --episodes 100 \
    --planner '{"return_best": true}' --groups kinet_l2 in forw forwinv
  "$PYTHON" docs/scripts/mpc_cpu.py test --runs $R --out runs/mpc_default/test_256x5 \
    --episodes 100 --planner "$BUDGET_256X5" --groups kinet_l2 in forw forwinv
  timed table2 "$PYTHON" -m kinet_rl.evaluate checkpoint=$R/blocks_topview/kinet.pt "${TABLE2[@]}" \
    hydra.run.dir=runs/table2_default
  timed kinet_random "$PYTHON" -m kinet_rl.train "${NO_MPC[@]}" env.background=random \
    data.name=blocks_top64_random exp_name=default_random_background \
    hydra.run.dir=$R/blocks_topview_random_background
  # Trained on random textures: tested on the fixed background (the comparison, 20 episodes) and
  # on random textures (the background cell, 20 episodes: Table II's background cell's scenes).
  timed background "$PYTHON" -m kinet_rl.evaluate \
    checkpoint=$R/blocks_topview_random_background/kinet.pt 'eval.methods=[kinet_keypoints_l2]' \
    eval.episodes=20 eval.generalization_episodes=20 'eval.num_objects=[]' \
    'eval.backgrounds=[random]' eval.workers=2 eval.videos=0 hydra.run.dir=runs/background_default
fi
# KINet's other costs (embedding distance, the paper's S, Chamfer) at the first budget, last.
"$PYTHON" docs/scripts/mpc_cpu.py test --runs $R --out runs/mpc_default/test_64x3 --episodes 100 \
  --planner '{"return_best": true}' --groups kinet
# The same group at the second budget (five methods, the keypoint-L2 row repeated; run for the
# third draw in three resumed invocations, docs/results.md "A third draw of the default model").
"$PYTHON" docs/scripts/mpc_cpu.py test --runs $R --out runs/mpc_default/test_256x5 --episodes 100 \
  --planner "$BUDGET_256X5" --groups kinet
