# Sourced by the run scripts of docs/scripts: `rows <run dir> <model> <seed> [<model> <seed> ...]`
# trains and scores those rows one after another with `python -m kinet_rl.tables`, the caller's
# `common` overrides and its PYTHON, in one run folder.
rows() {
  local dir=$1
  shift
  while (($#)); do
    "$PYTHON" -m kinet_rl.tables "${common[@]}" "tables.models=[$1]" "tables.seeds=[$2]" \
      "hydra.run.dir=$dir"
    shift 2
  done
}
