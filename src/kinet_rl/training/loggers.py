"""TorchRL logger construction (CSV by default; TensorBoard or W&B selectable) and media logging."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from PIL import Image
from torchrl.record.loggers import Logger, TensorboardLogger, WandbLogger, get_logger

LOGGER_KINDS = ("csv", "tensorboard", "wandb")
#: Files :func:`log_media` takes: still images and animated GIFs.
MEDIA_SUFFIXES = (".png", ".gif")


def make_logger(
    kind: str,
    run_dir: str | Path,
    exp_name: str,
    state_dict: Mapping[str, Any] | None = None,
    wandb_kwargs: Mapping[str, Any] | None = None,
) -> Logger:
    """Builds a TorchRL logger writing under ``run_dir/logs``; ``state_dict`` resumes one."""
    if kind not in LOGGER_KINDS:
        raise ValueError(f"logger.kind={kind!r} is not one of {LOGGER_KINDS}.")
    logger = get_logger(
        kind,
        logger_name=str(Path(run_dir) / "logs"),
        experiment_name=exp_name,
        state_dict=state_dict,
        wandb_kwargs=dict(wandb_kwargs or {}),
    )
    assert logger is not None
    return logger


def log_media(logger: Logger, name: str, path: Path, step: int) -> None:
    """Shows a PNG or GIF file of the run in the logger: a TensorBoard image (GIFs play there), a
    W&B image or video. CSV runs (and other loggers) keep the file itself as the record.

    The file's own bytes go to TensorBoard, so no video encoder (moviepy) is needed.
    """
    if path.suffix not in MEDIA_SUFFIXES:
        raise ValueError(f"{path} is not a {' or '.join(MEDIA_SUFFIXES)} file.")
    if isinstance(logger, TensorboardLogger):
        from tensorboard.compat.proto.summary_pb2 import Summary

        with Image.open(path) as image:
            width, height = image.size
        encoded = Summary.Image(
            height=height, width=width, colorspace=3, encoded_image_string=path.read_bytes()
        )
        summary = Summary(value=[Summary.Value(tag=name, image=encoded)])
        # SummaryWriter.add_image re-encodes arrays and add_video needs moviepy; a file's bytes
        # go in through the writer's event file, as add_video does itself.
        logger.experiment._get_file_writer().add_summary(summary, step)
    elif isinstance(logger, WandbLogger):
        import wandb

        media = (
            wandb.Video(str(path), format="gif")
            if path.suffix == ".gif"
            else wandb.Image(str(path))
        )
        # log_scalar sends any W&B value with the step of its name's prefix (e.g. "val/step").
        logger.log_scalar(name, media, step=step)  # type: ignore[arg-type]
