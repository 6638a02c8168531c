# Sourced by the YCB run scripts of docs/scripts: `ycb_row <camera> <size> <model> <method> <seed>
# [training overrides]` trains `+exp=ycb_<camera>view_<model>` (model `kinet`: `ycb_<camera>view`)
# at the cpu scale and that image size as `ycb_<camera>view<size>[_<model>][_seed<seed>]`
# (runs/<name>_cpu), then plans it with <method> on the YCB MPC protocol's 100 test episodes
# (seeds 50000-50099, 3 objects, T = 30, 64 x 3, one worker), with the caller's PYTHON.
# Resumable: a row whose MPC finished is skipped; training and evaluation each resume where they
# stopped.
ycb_mpc=(eval.episodes=100 eval.num_steps=30 "eval.geometries=[train]" "eval.backgrounds=[]"
  eval.workers=1 eval.videos=0 "eval.num_objects=[]")
ycb_row() {
  local camera=$1 size=$2 model=$3 method=$4 seed=$5
  local exp=ycb_${camera}view name=ycb_${camera}view$size
  if [[ $model != kinet ]]; then exp+=_$model name+=_$model; fi
  if [[ $seed != 0 ]]; then name+=_seed$seed; fi
  [[ -f runs/${name}_cpu/rearrangement/rearrangement.json ]] && return
  local run=(+exp=$exp +scale=cpu env.image_size=$size exp_name=$name seed=$seed trainer.seed=$seed)
  "$PYTHON" -m kinet_rl.train "${run[@]}" "${@:6}"
  "$PYTHON" -m kinet_rl.evaluate "${run[@]}" "${ycb_mpc[@]}" "eval.methods=[$method]"
}
