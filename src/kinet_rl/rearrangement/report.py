"""Rearrangement report: distance-to-goal plot, markdown tables, JSON and GIF videos."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from kinet_rl.atomic import atomic_write, atomic_write_json, atomic_write_text
from kinet_rl.envs.geometry import normalised_to_pixels
from kinet_rl.evaluation.images import draw_keypoints, image_grid, save_line_plot, upscale
from kinet_rl.rearrangement.results import EpisodeResult, RearrangementResults

VIDEO_SCALE = 4


def plot_curves(
    by_method: Mapping[str, Mapping[str, Any]], labels: Mapping[str, str], path: Path, title: str
) -> Path:
    """Mean distance to goal (mm) over pushes with its 95%-interval band, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for method, stats in by_method.items():
        mean = np.asarray(stats["mean_curve"]) * 1e3
        half = np.asarray(stats["ci95_curve"]) * 1e3
        steps = np.arange(len(mean))
        ax.plot(steps, mean, label=f"{labels.get(method, method)} (n={stats['episodes']})")
        ax.fill_between(steps, mean - half, mean + half, alpha=0.2)
    return save_line_plot(fig, ax, path, "push t", "mean object distance to goal [mm]", title)


def markdown(results: RearrangementResults, plot_name: str) -> str:
    """The markdown section: settings, comparison table, Table II layout and backgrounds."""
    settings, labels = results.settings, results.labels
    task, scene = settings.task, settings.scene
    lines = [
        "## Rearrangement (GraphMPC)",
        "",
        f"Scene: {scene.task}, {scene.num_objects} objects, {scene.camera} camera, "
        f"{scene.image_size} px, geometry {scene.geometry}, background {scene.background}. "
        f"T = {task.num_steps} pushes; goals made by {task.goal_pushes} random object pushes from "
        f"the start (reachable). Distances are ground truth, mean over objects, in mm; success = "
        f"every object within {task.success_threshold * 1e3:.0f} mm of its goal at T. "
        f"Mean ± 95% interval over episodes (Student's t; success: Wilson). "
        f"{settings.split.capitalize()} episodes, seeds {settings.first_seed} + i. "
        f"Planner of every method: {budget_text(settings.planner)}. "
        "SSIM: structural similarity of the camera image to the goal image at T, which needs no "
        "object state (the metric of a real robot); rho: Spearman's rank correlation of the SSIM "
        "with the distance over every push of every episode (-1: it tracks the distance "
        "perfectly).",
        "",
        f"![distance to goal]({plot_name})",
        "",
        "| method | episodes | start [mm] | final [mm] | success | final SSIM | rho(SSIM, distance) |",
        "|---|---|---|---|---|---|---|",
    ]
    for condition in results.conditions("comparison"):
        for method, stats in results.stats(condition).items():
            lines.append(
                f"| {labels.get(method, method)} | {stats['episodes']} | "
                f"{stats['initial_distance'] * 1e3:.1f} | {_final(stats)} | {success_text(stats)} "
                f"| {_number(stats['final_goal_ssim'])} | {_number(stats['goal_ssim_spearman'])} |"
            )
    kinet = labels.get(settings.kinet_method, settings.kinet_method)
    cells = {
        (c.scene.num_objects, c.scene.geometry): results.stats(c).get(settings.kinet_method)
        for c in results.conditions("generalization")
    }
    if cells:
        geometries = [g for g in settings.geometries if any(key[1] == g for key in cells)]
        lines += [
            "",
            f"Generalization ({kinet} distance at T, mm, start in brackets; paper Table II layout):",
            "",
            "| N | " + " | ".join(f"geom_{g}" for g in geometries) + " |",
            "|---|" + "---|" * len(geometries),
        ]
        for n in settings.num_objects:
            row = [_final(cells.get((n, g)), with_start=True) for g in geometries]
            lines.append(f"| {n} | " + " | ".join(row) + " |")
    backgrounds = results.conditions("background")
    if backgrounds:
        lines += [
            "",
            "Backgrounds (final distance at T, mm):",
            "",
            f"| background | {kinet} | {labels.get('random', 'random')} |",
            "|---|---|---|",
        ]
        for condition in backgrounds:
            stats = results.stats(condition)
            lines.append(
                f"| {condition.scene.background} | {_final(stats.get(settings.kinet_method))} | "
                f"{_final(stats.get('random'))} |"
            )
    return "\n".join(lines) + "\n"


def _final(stats: dict[str, Any] | None, with_start: bool = False) -> str:
    if stats is None:
        return "-"
    text = f"{stats['final_distance'] * 1e3:.1f} ± {stats['final_distance_ci95'] * 1e3:.1f}"
    return f"{text} ({stats['initial_distance'] * 1e3:.1f})" if with_start else text


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def success_text(stats: Mapping[str, Any]) -> str:
    """A success rate with its 95% Wilson interval, e.g. ``45% [26, 66]``."""
    low, high = stats["success_ci95"]
    return f"{100 * stats['success_rate']:.0f}% [{100 * low:.0f}, {100 * high:.0f}]"


def budget_text(planner: Mapping[str, Any]) -> str:
    """A planner budget in words, e.g. ``64 candidates x 3 iterations (top 8), horizon 1, cem``."""
    text = (
        f"{planner['num_candidates']} candidates x {planner['optim_steps']} iterations "
        f"(top {planner['top_k']}), horizon {planner.get('planning_horizon', 1)}"
    )
    return f"{text}, {planner['update_rule']}" if "update_rule" in planner else text


def video_frames(result: EpisodeResult) -> list[np.ndarray]:
    """Frames of a recorded episode: current image with keypoints beside the goal image."""
    if result.goal_pixels is None:
        raise ValueError("The episode was not recorded (run it with record=True).")
    size = result.goal_pixels.shape[0]
    if result.goal_keypoints is not None:
        goal = draw_keypoints(result.goal_pixels, _pixels(result.goal_keypoints, size), VIDEO_SCALE)
    else:
        goal = upscale(result.goal_pixels, VIDEO_SCALE)
    frames = []
    for t, frame in enumerate(result.frames):
        if t < len(result.keypoints):
            current = draw_keypoints(frame, _pixels(result.keypoints[t], size), VIDEO_SCALE)
        else:
            current = upscale(frame, VIDEO_SCALE)
        frames.append(image_grid([[current, goal]]))
    return frames


def _pixels(keypoints: np.ndarray, size: int) -> torch.Tensor:
    return normalised_to_pixels(torch.as_tensor(keypoints), size)


def write_video(result: EpisodeResult, path: Path, fps: float = 4.0) -> Path:
    """Writes an episode GIF (current | goal) atomically."""
    import imageio.v3 as iio

    frames = np.stack(video_frames(result))
    data = iio.imwrite("<bytes>", frames, extension=".gif", duration=1000.0 / fps, loop=0)
    with atomic_write(path, "wb") as f:
        f.write(data)
    return path


def write_report(out_dir: Path, results: RearrangementResults) -> list[Path]:
    """Writes ``rearrangement.png``, ``rearrangement.md``, ``rearrangement.json`` and videos."""
    out_dir.mkdir(parents=True, exist_ok=True)
    settings = results.settings
    files = [
        plot_curves(
            results.stats(condition),
            results.labels,
            out_dir / "rearrangement.png",
            f"Rearrangement, {settings.scene.num_objects} objects",
        )
        for condition in results.conditions("comparison")
    ]
    for condition in results.conditions("background"):
        path = out_dir / f"rearrangement_{condition.name}.png"
        files.append(plot_curves(results.stats(condition), results.labels, path, condition.name))
    for condition in results.conditions("comparison"):
        for result in results.episodes[condition].get(settings.kinet_method, []):
            if result.frames:
                files.append(write_video(result, out_dir / f"rearrangement_seed{result.seed}.gif"))
    atomic_write_text(out_dir / "rearrangement.md", markdown(results, "rearrangement.png"))
    atomic_write_json(
        out_dir / "rearrangement.json",
        {"summary": results.summary(), "settings": settings.as_dict()},
    )
    return [*files, out_dir / "rearrangement.md", out_dir / "rearrangement.json"]
