#!/usr/bin/env bash
# Table I's side camera at 96 px (24x24 heatmaps), the default-scale study's fix for the side-camera
# detector, at the cpu scale on one copy of the data: collect `tables_cpu_side96` (the cpu-scale
# side-camera data rendered at 96 px), then seeds 0, 1, 2 of the rows a part names, in three chains
# of rows with one torch thread each (3 jobs on 2 cores). Each row is trained and scored by
# `python -m kinet_rl.tables`; its MPC stage is cut to 4 episodes (not reported: the MPC tables are
# on the top camera). Run from the repository root:
#
#   bash docs/scripts/side96_cpu.sh [part]
#
# Parts: `first` (the default; KINet, IN and IN-full, run in a session of 2026-12-03), `baselines`
# (Forw, ForwInv, VisIN; run in a session of 2026-12-06: 1 h 30 min with the collection), `determ`
# and `no_ctr` (KINet-determ, KINet-no-ctr; measured for KINet-determ seeds 0-1 in that session:
# 70 min per seed with two jobs on 2 cores, so 100-115 min with three; about a session per part),
# `ablations` (what a session of 2026-12-06 ran after KINet-determ seeds 0-1: KINet-determ seed 2
# and KINet-no-ctr seeds 0-2 in two chains of two rows, one per core, so each row gets a core).
#
# Resumable: the collection and every row resume where they stopped, a finished row is skipped.
set -euo pipefail
export OMP_NUM_THREADS=1 MUJOCO_GL="${MUJOCO_GL:-egl}"
PYTHON="${PYTHON:-python}"
cpu_scale=('data.name=tables_cpu_{camera}96' env.image_size=96 data.num_episodes=1250
  data.num_workers=2 data.chunk_episodes=25 data.generalization=null trainer.steps=10000
  trainer.batch_size=32 trainer.eval_every=1000 trainer.checkpoint_every=1000 trainer.log_every=100
  report.rearrangement_episodes=0)
quoted=$(printf "'%s'," "${cpu_scale[@]}")
common=(tables=cpu "tables.overrides=[${quoted%,}]" 'tables.generalization_models=[]'
  'tables.mpc_budgets=null' '+tables.mpc_budgets={64x3:{num_candidates:64,optim_steps:3,top_k:8}}'
  tables.eval.episodes=4 'tables.cameras=[side]' tables.mpc_camera=side)
"$PYTHON" -m kinet_rl.collect +exp=blocks_sideview "${cpu_scale[@]/\{camera\}/side}"
source "$(dirname "$0")/table_rows.sh"
mkdir -p runs
case "${1:-first}" in
  first)
    rows runs/side96_a kinet 0 > runs/side96_a.log 2>&1 &
    rows runs/side96_b kinet 1 in 0 in 1 in 2 > runs/side96_b.log 2>&1 &
    rows runs/side96_c kinet 2 in_full 0 in_full 1 in_full 2 > runs/side96_c.log 2>&1 &
    ;;
  baselines)
    for seed in 0 1 2; do
      rows runs/side96_base_$seed forw $seed forwinv $seed visin $seed \
        > runs/side96_base_$seed.log 2>&1 &
    done
    ;;
  determ | no_ctr)
    for seed in 0 1 2; do
      rows runs/side96_$1_$seed kinet_$1 $seed > runs/side96_$1_$seed.log 2>&1 &
    done
    ;;
  ablations)
    rows runs/side96_ablations_a kinet_determ 2 kinet_no_ctr 1 > runs/side96_ablations_a.log 2>&1 &
    rows runs/side96_ablations_b kinet_no_ctr 0 kinet_no_ctr 2 > runs/side96_ablations_b.log 2>&1 &
    ;;
  *) echo "usage: $0 [first|baselines|determ|no_ctr|ablations]" >&2; exit 2 ;;
esac
wait
