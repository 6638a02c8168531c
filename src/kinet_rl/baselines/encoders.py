"""Convolutional encoders of whole images and of fixed-size crops around objects."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from kinet_rl.models.keypoints import pixels_to_input

#: Side of the feature map that :class:`ConvEncoder` flattens (keeps where things are).
POOLED_SIZE = 4


class ConvEncoder(nn.Module):
    """Strided conv stack -> ``POOLED_SIZE`` x ``POOLED_SIZE`` map -> flattened linear features.

    The spatial map is flattened rather than averaged, so the features keep where things are.

    Args:
        out_dim: ``D`` of the output features.
        channels: Width of every conv layer.
        num_down: Stride-2 conv layers (each halves the resolution).
        normalise: Apply a parameter-free LayerNorm to the output (features of norm ``sqrt(D)``).
    """

    def __init__(
        self, out_dim: int, channels: int = 32, num_down: int = 3, normalise: bool = False
    ) -> None:
        super().__init__()
        if out_dim < 1 or channels < 1 or num_down < 1:
            raise ValueError(
                f"out_dim, channels and num_down must be positive, got {out_dim}, {channels}, "
                f"{num_down}."
            )
        layers: list[nn.Module] = []
        in_ch = 3
        for _ in range(num_down):
            layers += [
                nn.Conv2d(in_ch, channels, 3, stride=2, padding=1),
                nn.GroupNorm(1, channels),
                nn.ReLU(),
            ]
            in_ch = channels
        layers += [
            nn.AdaptiveAvgPool2d(POOLED_SIZE),
            nn.Flatten(),
            nn.Linear(channels * POOLED_SIZE**2, out_dim),
        ]
        if normalise:
            layers.append(nn.LayerNorm(out_dim, elementwise_affine=False))
        self.net = nn.Sequential(*layers)

    def forward(self, pixels: Tensor) -> Tensor:
        """``[*B, H, W, 3]`` uint8 (0-255) or float (0-1) images -> ``[*B, D]`` features."""
        batch = pixels.shape[:-3]
        return self.net(pixels_to_input(pixels)).reshape(*batch, -1)


def crop_objects(pixels: Tensor, centres: Tensor, crop_size: float, resolution: int) -> Tensor:
    """Bilinear square crops centred on points of the image (zeros outside the image).

    Args:
        pixels: ``[B, H, W, 3]`` uint8 (0-255) or float (0-1) images (``H == W``).
        centres: ``[B, N, 2]`` crop centres in normalised image coordinates (``[-1, 1]``, x right,
            y down, ``align_corners=False``).
        crop_size: Side of each crop in image pixels.
        resolution: Side of each output crop in samples.

    Returns:
        ``[B, N, resolution, resolution, 3]`` float crops in ``[0, 1]`` (out-of-image: 0).
    """
    if pixels.dim() != 4 or centres.dim() != 3 or centres.shape[0] != pixels.shape[0]:
        raise ValueError(
            f"Expected pixels [B, H, W, 3] and centres [B, N, 2]; got {tuple(pixels.shape)} and "
            f"{tuple(centres.shape)}."
        )
    batch, num = centres.shape[:2]
    image = pixels_to_input(pixels) + 0.5  # [B, 3, H, W] in [0, 1]
    half = crop_size / pixels.shape[-2]  # half side in normalised units: (size / 2) / (W / 2)
    steps = (
        torch.arange(resolution, device=centres.device, dtype=centres.dtype) + 0.5
    ) / resolution
    offsets = (2.0 * steps - 1.0) * half  # sample centres across the crop
    grid_y, grid_x = torch.meshgrid(offsets, offsets, indexing="ij")
    grid = torch.stack([grid_x, grid_y], dim=-1)  # [r, r, 2]
    grid = centres.reshape(batch * num, 1, 1, 2) + grid
    crops = F.grid_sample(
        image.repeat_interleave(num, dim=0), grid, mode="bilinear", align_corners=False
    )
    return crops.permute(0, 2, 3, 1).reshape(batch, num, resolution, resolution, 3)
