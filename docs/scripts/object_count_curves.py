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


def count_cells(path: Path) -> tuple[str, dict[tuple[int, str], dict]]:
    """The run's KINet method and its summary cells by (object count, geometry)."""
    data = json.loads(path.read_text())
    method = data["settings"]["kinet_method"]
    cells = {
        (int(match["n"]), match["geometry"]): cell[method]
        for name, cell in data["summary"].items()
        if (match := CELL.fullmatch(name)) and method in cell
    }
    if not cells:
        raise SystemExit(f"{path} has no object-count cells of {method}; run with eval.num_objects")
    return method, cells


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("json", type=Path)
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    method, cells = count_cells(args.json)
    curves = {f"{n} objects ({geometry})": cell for (n, geometry), cell in cells.items()}
    print(plot_curves(curves, {}, args.out, f"MPC by object count: {method}"))


if __name__ == "__main__":
    main()
