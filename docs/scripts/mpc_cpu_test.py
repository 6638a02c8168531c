"""Headline MPC table on TEST episodes (split=test, seeds 50000 + i) with the validation-chosen planner,
as run for docs/results.md: `python docs/scripts/mpc_cpu_test.py <out> 100 <planner JSON>` from the
repository root (models from runs/tables_cpu). Kept as run."""

import json
import sys
import time
from pathlib import Path

from kinet_rl.models import KINetWorldModel
from kinet_rl.pipeline import evaluate_rearrangement
from kinet_rl.rearrangement.settings import RearrangementSettings


def main():
    out_root = Path(sys.argv[1])
    episodes = int(sys.argv[2])
    planner = json.loads(sys.argv[3])
    only = sys.argv[4].split(",") if len(sys.argv) > 4 else None
    out_root.mkdir(parents=True, exist_ok=True)
    runs = Path("/work/main/runs/tables_cpu")
    from kinet_rl.baselines.image_models import ImageForwardInverseModel, ImageForwardModel
    from kinet_rl.baselines.object_models import ObjectInteractionModel

    loaders = {
        "kinet": lambda: KINetWorldModel.from_checkpoint(runs / "blocks_topview/kinet.pt").eval(),
        "in": lambda: ObjectInteractionModel.from_checkpoint(
            runs / "blocks_topview_in/model.pt"
        ).eval(),
        "forw": lambda: ImageForwardModel.from_checkpoint(
            runs / "blocks_topview_forw/model.pt"
        ).eval(),
        "forwinv": lambda: ImageForwardInverseModel.from_checkpoint(
            runs / "blocks_topview_forwinv/model.pt"
        ).eval(),
    }
    groups = [
        (
            "kinet",
            [
                "kinet_keypoints_l2",
                "kinet_graph_distance",
                "kinet_keypoints",
                "kinet_graph",
                "kinet_graph_dot",
            ],
            "kinet",
        ),
        ("kinet_l2", ["kinet_keypoints_l2"], "kinet"),  # only the chosen KINet planner (second budget)
        ("refs", ["random", "oracle"], None),
        ("in", ["model_mpc"], "in"),
        ("forw", ["model_mpc"], "forw"),
        ("forwinv", ["model_mpc"], "forwinv"),
    ]
    for name, methods, kind in groups:
        if only and name not in only:
            continue
        path = out_root / f"{name}.json"
        if path.exists():
            continue
        model = loaders[kind]() if kind else None
        s = RearrangementSettings.from_dicts(
            {
                "episodes": episodes,
                "methods": methods,
                "num_steps": 40,
                "workers": 2,
                "videos": 0,
                "split": "test",
                "planner": planner,
                "kinet_method": "kinet_keypoints_l2",
            },
            {"task": "blocks", "num_objects": 3, "camera": "top", "image_size": 64},
        )
        t = time.time()
        summ = evaluate_rearrangement(model, s, out_root / name)["summary"]["comparison"]
        out = {m: v for m, v in summ.items()}
        out["_wall_s"] = time.time() - t
        out["_planner"] = planner
        path.write_text(json.dumps(out, indent=1))
        print(
            name,
            {
                m: (
                    round(1e3 * v["final_distance"], 1),
                    round(1e3 * v["final_distance_ci95"], 1),
                    v["success_rate"],
                )
                for m, v in summ.items()
            },
            round(out["_wall_s"]),
            "s",
            flush=True,
        )


if __name__ == "__main__":
    main()
