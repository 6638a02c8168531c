"""The comparison tables of ``python -m kinet_rl.tables``: their settings (the ``tables`` config
group), forward errors over seeds, markdown, plots.

Units and protocol are the same for every row: Table I is the forward error in millimetres on the
same held-out test sequences for every model of a camera, averaged over the sequences of each
training seed, then mean ± 95% interval (Student's t) over training seeds; the detector floor
reads object motion off the keypoints KINet detects in the true next frames. The MPC table is the
ground-truth mean object distance to the goal after ``T`` pushes (mean ± 95% interval over the
same episodes, or over training seeds when several plan) and the success rate with its Wilson
interval; Table II is the MPC final distance of the generalization models (KINet, KINet-determ,
V-CDN) per object count and geometry.
"""

from kinet_rl.comparison.markdown import (
    accuracy_section,
    generalization_sections,
    horizon_table,
    label_of,
    mpc_table,
    table_i,
    table_ii,
)
from kinet_rl.comparison.plots import learning_curve, plot_learning_curves, plot_mpc_curves
from kinet_rl.comparison.settings import CAMERAS, LABELS, TASKS, TablesSettings, Variant

__all__ = [
    "CAMERAS",
    "LABELS",
    "TASKS",
    "TablesSettings",
    "Variant",
    "accuracy_section",
    "generalization_sections",
    "horizon_table",
    "label_of",
    "learning_curve",
    "mpc_table",
    "plot_learning_curves",
    "plot_mpc_curves",
    "table_i",
    "table_ii",
]
