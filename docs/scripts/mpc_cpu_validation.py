"""Choose the MPC cost and planner settings on validation episodes (split=validation), as run for
docs/results.md: `python docs/scripts/mpc_cpu_validation.py 50` from the repository root (outputs in
/work/exp/val; models from runs/tables_cpu). Kept as run; the library calls are the documented ones."""

import json
import sys
import time
from pathlib import Path

import torch

from kinet_rl.baselines import *  # noqa
from kinet_rl.models import KINetWorldModel
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings


def main():
    OUT = Path("/work/exp/val")
    OUT.mkdir(parents=True, exist_ok=True)
    EPISODES = int(sys.argv[1]) if len(sys.argv) > 1 else 50
    KINET = KINetWorldModel.from_checkpoint(
        "/work/main/runs/tables_cpu/blocks_topview/kinet.pt"
    ).eval()

    def baseline(path):
        torch.load(path, weights_only=True)
        from kinet_rl.baselines.object_models import ObjectInteractionModel

        return ObjectInteractionModel.from_checkpoint(path).eval()

    BASE = {
        "planning_horizon": 1,
        "optim_steps": 3,
        "num_candidates": 64,
        "top_k": 8,
        "update_rule": "cem",
        "temperature": 0.5,
        "min_std": 0.05,
        "max_std": 1.0,
    }
    VARIANTS = [  # name, methods, model, planner overrides
        (
            "costs",
            [
                "kinet_graph_distance",
                "kinet_graph",
                "kinet_graph_dot",
                "kinet_keypoints",
                "kinet_keypoints_l2",
            ],
            "kinet",
            {},
        ),
        ("refs", ["random", "oracle"], None, {}),
        ("in", ["model_mpc"], "in", {}),
        ("best", ["kinet_graph_distance", "kinet_keypoints_l2"], "kinet", {"return_best": True}),
        ("in_best", ["model_mpc"], "in", {"return_best": True}),
        ("oracle_best", ["random", "oracle"], None, {"return_best": True}),
        (
            "l2_best_elites",
            ["kinet_keypoints_l2"],
            "kinet",
            {"return_best": True, "keep_elites": 2},
        ),
        (
            "l2_best_mppi",
            ["kinet_keypoints_l2"],
            "kinet",
            {"return_best": True, "update_rule": "mppi"},
        ),
        (
            "l2_best_h3",
            ["kinet_keypoints_l2"],
            "kinet",
            {"return_best": True, "planning_horizon": 3},
        ),
    ]
    only = sys.argv[2].split(",") if len(sys.argv) > 2 else None
    for name, methods, model_kind, extra in VARIANTS:
        if only and name not in only:
            continue
        path = OUT / f"{name}.json"
        if path.exists():
            continue
        model = {"kinet": KINET, "in": None, None: None}[model_kind]
        if model_kind == "in":
            model = baseline("/work/main/runs/tables_cpu/blocks_topview_in/model.pt")
        s = RearrangementSettings.from_dicts(
            {
                "episodes": EPISODES,
                "methods": methods,
                "num_steps": 40,
                "workers": 2,
                "videos": 0,
                "split": "validation",
                "planner": {**BASE, **extra},
            },
            {"task": "blocks", "num_objects": 3, "camera": "top", "image_size": 64},
        )
        t = time.time()
        summ = evaluate_rearrangement(model, s, OUT / name)["summary"]["comparison"]
        out = {
            m: {
                k: v[k]
                for k in (
                    "episodes",
                    "initial_distance",
                    "final_distance",
                    "final_distance_ci95",
                    "success_rate",
                    "success_ci95",
                )
            }
            for m, v in summ.items()
        }
        out["_wall_s"] = time.time() - t
        out["_planner"] = {**BASE, **extra}
        path.write_text(json.dumps(out, indent=1))
        print(
            name,
            {
                m: (
                    round(1e3 * v["final_distance"], 1),
                    round(1e3 * v["final_distance_ci95"], 1),
                    v["success_rate"],
                )
                for m, v in out.items()
                if not m.startswith("_")
            },
            round(out["_wall_s"]),
            "s",
            flush=True,
        )


if __name__ == "__main__":
    main()
