"""kinet_rl: unsupervised keypoint forward models (KINet) and graph MPC for robotic pushing."""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
