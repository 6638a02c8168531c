"""Evaluation: keypoint and forward-prediction metrics, camera projection, reports."""

from __future__ import annotations
