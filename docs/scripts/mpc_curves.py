"""MPC distance curves with 95% bands from the group JSONs of ``mpc_cpu.py``.

Each row is ``LABEL=group.json:method`` (a group JSON maps method names to their summaries); the
rows share a plot, one line and band per row, saved atomically as PNG.

Usage: python docs/scripts/mpc_curves.py out.png "64 x 3" \
    "KINet (keypoint L2)=docs/runs/default_rows/mpc_64x3/kinet_l2.json:kinet_keypoints_l2" \
    "oracle=docs/runs/mpc_cpu/test/refs.json:oracle"
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinet_rl.rearrangement.report import plot_curves


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    parser.add_argument("title")
    parser.add_argument("rows", nargs="+", help="LABEL=group.json:method")
    args = parser.parse_args()
    by_label = {}
    for row in args.rows:
        label, sep, source = row.partition("=")
        path, colon, method = source.rpartition(":")
        if not (sep and colon):
            raise SystemExit(f"{row!r}: give each row as LABEL=path/to/group.json:method")
        group = json.loads(Path(path).read_text())
        if method not in group:
            found = [k for k in group if not k.startswith("_")]
            raise SystemExit(f"{path} has no method {method!r}; it has {found}")
        by_label[label] = group[method]
    print(plot_curves(by_label, {}, args.out, args.title))


if __name__ == "__main__":
    main()
