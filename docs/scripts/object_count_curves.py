"""The paper's Fig. 6 from one rearrangement JSON: distance to the goal over pushes for each
object count of its generalization cells (mean over objects, 95%-interval bands over episodes).

Usage: python docs/scripts/object_count_curves.py runs/x/rearrangement/rearrangement.json out.png
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from kinet_rl.rearrangement.report import plot_curves

CELL = re.compile(r"n(?P<n>\d+)_geom_(?P<geometry>\w+)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("json", type=Path)
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    data = json.loads(args.json.read_text())
    method = data["settings"]["kinet_method"]
    curves = {
        f"{match['n']} objects ({match['geometry']})": cell[method]
        for name, cell in data["summary"].items()
        if (match := CELL.fullmatch(name)) and method in cell
    }
    if not curves:
        raise SystemExit(f"{args.json} has no object-count cells of {method}; run with eval.num_objects")
    print(plot_curves(curves, {}, args.out, f"MPC by object count: {method}"))


if __name__ == "__main__":
    main()
