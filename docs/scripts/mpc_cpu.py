"""The cpu-scale MPC study of docs/results.md: choose costs and planner settings on validation
episodes, and plan the tables' models with KINet's other costs on test episodes.

The published MPC tables are configs of ``python -m kinet_rl.tables`` (Fig. 4a:
``tables=fig4a_mpc_cpu``); this tool plans their seed-0 models with what the tables do not vary
(several costs of one model, planner variants). Run from the repository root, after the tables
trained the seed-0 rows into ``--runs`` (default ``runs/tables_cpu``; the Fig. 4a config's:
``--runs runs/tables_fig4a_mpc_cpu``)::

    python docs/scripts/mpc_cpu.py validation --out runs/mpc_cpu/validation --episodes 50
    python docs/scripts/mpc_cpu.py test --out runs/mpc_cpu/test_64x3 --episodes 100 \
        --planner '{"return_best": true}'
    python docs/scripts/mpc_cpu.py test --out runs/mpc_cpu/test_256x5 --episodes 100 \
        --planner '{"return_best": true, "num_candidates": 256, "optim_steps": 5, "top_k": 16}' \
        --groups kinet_l2 in refs

Each group is one :func:`kinet_rl.pipeline.evaluate_rearrangement` (3 blocks, top camera, 64 px,
T = 40, ``--workers`` worker processes, default 2) written to ``<out>/<group>.json`` with its wall
time and planner; a group whose JSON exists is skipped, so an interrupted run resumes (episode by
episode, from the episodes stored under ``<out>/<group>/``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from kinet_rl.baselines.image_models import ImageForwardInverseModel, ImageForwardModel
from kinet_rl.baselines.object_models import ObjectInteractionModel
from kinet_rl.models import KINetWorldModel
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings

SCENE = {"task": "blocks", "num_objects": 3, "camera": "top", "image_size": 64}
#: The evaluation's budget before return_best was chosen (64 x 3, top 8, H = 1, CEM).
BASE_PLANNER = {
    "planning_horizon": 1, "optim_steps": 3, "num_candidates": 64, "top_k": 8,
    "update_rule": "cem", "temperature": 0.5, "min_std": 0.05, "max_std": 1.0,
}  # fmt: skip
MODELS = {  # row -> (class, checkpoint in the tables' run folder)
    "kinet": (KINetWorldModel, "blocks_topview/kinet.pt"),
    "in": (ObjectInteractionModel, "blocks_topview_in/model.pt"),
    "forw": (ImageForwardModel, "blocks_topview_forw/model.pt"),
    "forwinv": (ImageForwardInverseModel, "blocks_topview_forwinv/model.pt"),
}
KINET_COSTS = [
    "kinet_graph_distance", "kinet_graph", "kinet_graph_dot", "kinet_keypoints",
    "kinet_keypoints_l2",
]  # fmt: skip
#: Validation groups: name, methods, model row, planner overrides of BASE_PLANNER.
VALIDATION = [
    ("costs", KINET_COSTS, "kinet", {}),
    ("refs", ["random", "oracle"], None, {}),
    ("in", ["model_mpc"], "in", {}),
    ("best", ["kinet_graph_distance", "kinet_keypoints_l2"], "kinet", {"return_best": True}),
    ("in_best", ["model_mpc"], "in", {"return_best": True}),
    ("oracle_best", ["random", "oracle"], None, {"return_best": True}),
    ("l2_best_elites", ["kinet_keypoints_l2"], "kinet", {"return_best": True, "keep_elites": 2}),
    ("l2_best_mppi", ["kinet_keypoints_l2"], "kinet", {"return_best": True, "update_rule": "mppi"}),
    ("l2_best_h3", ["kinet_keypoints_l2"], "kinet", {"return_best": True, "planning_horizon": 3}),
]
#: Test groups (one planner for every group): name, methods, model row.
TEST = [
    ("kinet", ["kinet_keypoints_l2", *KINET_COSTS[:-1]], "kinet"),
    ("kinet_l2", ["kinet_keypoints_l2"], "kinet"),
    ("refs", ["random", "oracle"], None),
    ("in", ["model_mpc"], "in"),
    ("forw", ["model_mpc"], "forw"),
    ("forwinv", ["model_mpc"], "forwinv"),
]


def run_group(
    out: Path, name: str, methods, model, planner, split: str, episodes: int, workers: int
) -> None:
    """One evaluation into ``<out>/<name>.json`` (skipped when the file exists)."""
    path = out / f"{name}.json"
    if path.exists():
        return
    eval_cfg = {"episodes": episodes, "methods": methods, "num_steps": 40, "workers": workers}
    eval_cfg |= {"videos": 0, "split": split, "planner": planner}
    settings = RearrangementSettings.from_dicts(eval_cfg, SCENE)
    start = time.time()
    summary = evaluate_rearrangement(model, settings, out / name)["summary"]["comparison"]
    result = {**summary, "_wall_s": time.time() - start, "_planner": planner}
    path.write_text(json.dumps(result, indent=1))
    finals = {
        m: f"{1e3 * v['final_distance']:.1f} ± {1e3 * v['final_distance_ci95']:.1f} mm, "
        f"{100 * v['success_rate']:.0f}%"
        for m, v in summary.items()
    }
    print(name, finals, f"{result['_wall_s']:.0f} s", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("split", choices=["validation", "test"])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--runs", type=Path, default=Path("runs/tables_cpu"))
    parser.add_argument("--planner", default="{}", help="test: JSON overrides of BASE_PLANNER")
    parser.add_argument("--groups", nargs="+", help="only these groups")
    parser.add_argument("--workers", type=int, default=2, help="episode worker processes")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)

    def load(row):
        if row is None:
            return None
        model_class, checkpoint = MODELS[row]
        return model_class.from_checkpoint(args.runs / checkpoint).eval()

    if args.split == "validation":
        groups = [(n, m, r, {**BASE_PLANNER, **extra}) for n, m, r, extra in VALIDATION]
    else:
        planner = {**BASE_PLANNER, **json.loads(args.planner)}
        groups = [(n, m, r, planner) for n, m, r in TEST]
    for name, methods, row, planner in groups:
        if args.groups is None or name in args.groups:
            run_group(
                args.out, name, methods, load(row), planner, args.split, args.episodes, args.workers
            )


if __name__ == "__main__":
    main()
