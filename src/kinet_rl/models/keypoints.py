"""Unsupervised keypoint detector ``f_kp`` and Transporter-style reconstructor ``f_rec``.

Coordinates: keypoints lie in ``[-1, 1]^2`` as ``(x, y)`` with x pointing right and y pointing
down in the image, so ``(-1, -1)`` is the centre of the top-left corner region and ``(1, 1)`` the
bottom-right one (``torch.nn.functional.grid_sample`` convention, ``align_corners=False``).

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.1; Transporter, Kulkarni et al.,
NeurIPS 2019.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import Tensor, nn


def pixels_to_input(pixels: Tensor) -> Tensor:
    """Turns ``[*B, H, W, 3]`` images into centred float ``[N, 3, H, W]`` network input.

    uint8 images are scaled from ``[0, 255]``, float images are taken to lie in ``[0, 1]``; both
    are shifted to ``[-0.5, 0.5]``. The result is a channels-last strided view (no copy for float).

    Args:
        pixels: ``[*B, H, W, 3]`` uint8 or float image batch.

    Returns:
        ``[N, 3, H, W]`` float32 with ``N = prod(B)``.
    """
    if pixels.dim() < 3 or pixels.shape[-1] != 3:
        raise ValueError(
            f"Expected images shaped [*B, H, W, 3] (channels last, RGB), got {tuple(pixels.shape)}; "
            "permute channel-first images with .permute(..., 2, 3, 1) first."
        )
    flat = pixels.reshape(-1, *pixels.shape[-3:])
    if flat.dtype == torch.uint8:
        flat = flat.float() / 255.0
    elif not flat.is_floating_point():
        raise TypeError(f"Images must be uint8 or float, got {pixels.dtype}.")
    return (flat - 0.5).permute(0, 3, 1, 2)


def pixel_grid(height: int, width: int, device: torch.device | None = None) -> Tensor:
    """Pixel-centre coordinates ``[H, W, 2]`` as ``(x, y)`` in ``[-1, 1]`` (align_corners=False)."""
    ys = (torch.arange(height, device=device, dtype=torch.float32) * 2 + 1) / height - 1
    xs = (torch.arange(width, device=device, dtype=torch.float32) * 2 + 1) / width - 1
    grid_y, grid_x = torch.meshgrid(ys, xs, indexing="ij")
    return torch.stack([grid_x, grid_y], dim=-1)


def spatial_soft_argmax(logits: Tensor) -> tuple[Tensor, Tensor]:
    """Expected ``(x, y)`` position under a spatial softmax of each map.

    Args:
        logits: ``[N, K, H, W]`` unnormalised heatmaps.

    Returns:
        ``pos`` ``[N, K, 2]`` in ``[-1, 1]`` and the normalised heatmaps ``[N, K, H, W]``.
    """
    n, k, h, w = logits.shape
    heat = logits.reshape(n, k, h * w).softmax(dim=-1)
    grid = pixel_grid(h, w, logits.device).reshape(h * w, 2)
    return heat @ grid, heat.reshape(n, k, h, w)


def gaussian_maps(pos: Tensor, height: int, width: int, std: float) -> Tensor:
    """Isotropic Gaussian blobs (peak 1) rendered at each keypoint.

    Args:
        pos: ``[N, K, 2]`` keypoints in ``[-1, 1]``.
        height: Map height.
        width: Map width.
        std: Standard deviation in normalised ``[-1, 1]`` units.

    Returns:
        ``[N, K, H, W]`` maps in ``[0, 1]``.
    """
    grid = pixel_grid(height, width, pos.device)  # [H, W, 2]
    sq_dist = (grid[None, None] - pos[:, :, None, None, :]).pow(2).sum(-1)
    return torch.exp(-sq_dist / (2 * std**2))


#: How far the gradients of keypoint features reach into the detector.
FEATURE_GRADS = ("none", "head", "encoder")

#: Image-to-heatmap downsampling factors of the detector (4: 16x16 heatmaps for 64 px images).
HEATMAP_STRIDES = (4, 2)


def fine_channels(channels: int) -> int:
    """Width of the 1/2-resolution level for a detector of width ``channels``."""
    return max(channels // 2, 1)


def _conv_block(in_ch: int, out_ch: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(in_ch, out_ch, 3, stride=stride, padding=1),
        nn.GroupNorm(1, out_ch),
        nn.ReLU(inplace=True),
    )


@dataclass
class EncodedFrames:
    """Outputs of :class:`KeypointDetector` for a batch of ``N`` frames.

    Attributes:
        pos: ``[N, K, 2]`` keypoints in ``[-1, 1]``.
        feat: ``[N, K, D]`` visual feature per keypoint.
        fine: ``[N, C/2, H/2, W/2]`` encoder features (skip level used by the reconstructor).
        coarse: ``[N, C, H/4, W/4]`` encoder features.
    """

    pos: Tensor
    feat: Tensor
    fine: Tensor
    coarse: Tensor

    def split(self, size: int) -> tuple[EncodedFrames, ...]:
        """Splits the batch into chunks of ``size`` frames."""
        parts = (t.split(size) for t in (self.pos, self.feat, self.fine, self.coarse))
        return tuple(EncodedFrames(*chunk) for chunk in zip(*parts, strict=True))


class _HalfResolutionHeatmaps(nn.Module):
    """Heatmaps at 1/2 resolution: the upsampled 1/4 features joined with the 1/2 level (U-Net
    style, like :class:`KeypointReconstructor`'s decoder), a conv, then a 1x1 conv to ``K`` maps."""

    def __init__(self, channels: int, num_keypoints: int) -> None:
        super().__init__()
        fine_ch = fine_channels(channels)
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.merge = _conv_block(channels + fine_ch, fine_ch)
        self.out = nn.Conv2d(fine_ch, num_keypoints, 1)

    def forward(self, coarse: Tensor, fine: Tensor) -> Tensor:
        return self.out(self.merge(torch.cat([self.up(coarse), fine], dim=1)))


class KeypointDetector(nn.Module):
    """Keypoint detector ``f_kp``: image -> ``K`` keypoints and a visual feature per keypoint.

    A strided conv encoder produces feature maps at 1/2 and 1/4 resolution; a 1x1 head turns the
    1/4 map into ``K`` heatmaps whose spatial soft-argmax gives the keypoints, and the
    heatmap-weighted average of the 1/4 features, projected to ``feat_dim``, gives ``phi_k``.
    With ``heatmap_stride = 2`` the heatmaps are at 1/2 resolution instead (32x32 for 64 px
    images), from the 1/4 features upsampled and joined with the 1/2 level; the feature pooling
    then uses the heatmaps summed over each 2x2 cell.
    The same weights encode the initial frame ``I_0`` and the current frame ``I_t``.

    With ``feat_dim = 0`` there is no feature head and ``phi_k`` is empty (``[N, K, 0]``): a
    detector of keypoint positions only, as V-CDN's perception module.

    Gradients that reach ``phi_k`` (from the forward and contrastive losses) never move the
    keypoints: the pooling weights are detached, and with ``feature_grad="head"`` so are the
    pooled features, so that only the projection learns; ``"encoder"`` lets them train the
    1/4-resolution encoder as well; ``"none"`` detaches the features (they stay a fixed random
    projection: the behaviour before this option existed, kept as an ablation).

    Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.1.

    Args:
        num_keypoints: ``K``.
        feat_dim: ``D``, size of each keypoint's visual feature (0: none).
        channels: ``C``, width of the 1/4-resolution features (the 1/2 level has ``C/2``).
        feature_grad: ``"head"`` or ``"encoder"``: how far feature gradients reach (see above).
        heatmap_stride: 4 (heatmaps at 1/4 of the image size) or 2 (at 1/2).
    """

    def __init__(
        self,
        num_keypoints: int = 6,
        feat_dim: int = 16,
        channels: int = 32,
        feature_grad: str = "head",
        heatmap_stride: int = 4,
    ) -> None:
        super().__init__()
        if num_keypoints < 1 or channels < 1:
            raise ValueError(
                f"num_keypoints and channels must be positive, got {num_keypoints} and {channels}."
            )
        if feat_dim < 0:
            raise ValueError(f"feat_dim must be >= 0 (0: no features), got {feat_dim}.")
        if feature_grad not in FEATURE_GRADS:
            raise ValueError(f"feature_grad={feature_grad!r}; choose one of {FEATURE_GRADS}.")
        if heatmap_stride not in HEATMAP_STRIDES:
            raise ValueError(f"heatmap_stride={heatmap_stride!r}; choose one of {HEATMAP_STRIDES}.")
        self.feature_grad = feature_grad
        self.heatmap_stride = heatmap_stride
        self.num_keypoints = num_keypoints
        self.feat_dim = feat_dim
        self.channels = channels
        fine_ch = fine_channels(channels)
        self.fine_net = nn.Sequential(_conv_block(3, fine_ch, 2), _conv_block(fine_ch, fine_ch))
        self.coarse_net = nn.Sequential(
            _conv_block(fine_ch, channels, 2), _conv_block(channels, channels)
        )
        self.heatmap_head: nn.Module
        if heatmap_stride == 4:
            self.heatmap_head = nn.Conv2d(channels, num_keypoints, 1)
        else:
            self.heatmap_head = _HalfResolutionHeatmaps(channels, num_keypoints)
        self.feat_head = nn.Linear(channels, feat_dim) if feat_dim > 0 else None

    def encode(self, pixels: Tensor) -> EncodedFrames:
        """Encodes ``[*B, H, W, 3]`` images (``H``, ``W`` divisible by 4); outputs are flat ``[N]``."""
        images = pixels_to_input(pixels)  # checks the layout first
        height, width = images.shape[-2:]
        if height % 4 or width % 4:
            raise ValueError(f"Image size {height}x{width} must be divisible by 4 (e.g. 64x64).")
        fine = self.fine_net(images)
        coarse = self.coarse_net(fine)
        if self.heatmap_stride == 4:
            pos, heat = spatial_soft_argmax(self.heatmap_head(coarse))
        else:
            pos, heat = spatial_soft_argmax(self.heatmap_head(coarse, fine))
            heat = F.avg_pool2d(heat, 2) * 4  # each 1/4-resolution cell's share, still sums to 1
        if self.feat_head is None:
            no_feat = pos.new_zeros(*pos.shape[:-1], 0)
            return EncodedFrames(pos=pos, feat=no_feat, fine=fine, coarse=coarse)
        maps = coarse.detach() if self.feature_grad == "head" else coarse
        pooled = torch.einsum("nkhw,nchw->nkc", heat.detach(), maps)
        feat = self.feat_head(pooled)
        if self.feature_grad == "none":
            feat = feat.detach()
        return EncodedFrames(pos=pos, feat=feat, fine=fine, coarse=coarse)

    def forward(self, pixels: Tensor) -> tuple[Tensor, Tensor]:
        """Detects keypoints.

        Args:
            pixels: ``[*B, H, W, 3]`` uint8 (0-255) or float (0-1) RGB images.

        Returns:
            ``pos`` ``[*B, K, 2]`` in ``[-1, 1]`` (x right, y down) and ``feat`` ``[*B, K, D]``.
        """
        batch = pixels.shape[:-3]
        enc = self.encode(pixels)
        return enc.pos.reshape(*batch, *enc.pos.shape[1:]), enc.feat.reshape(
            *batch, *enc.feat.shape[1:]
        )


def _blob_masks(pos_src: Tensor, pos_tgt: Tensor, height: int, width: int, std: float):
    """Gaussian blobs ``[N, K, H, W]`` at the target keypoints and the keep mask ``[N, 1, H, W]``.

    The keep mask is 0 under every source and target blob, 1 far from all of them.
    """
    blob_src = gaussian_maps(pos_src, height, width, std)
    blob_tgt = gaussian_maps(pos_tgt, height, width, std)
    return blob_tgt, ((1 - blob_src) * (1 - blob_tgt)).prod(dim=1, keepdim=True)


def transport(
    source: Tensor, target: Tensor, pos_src: Tensor, pos_tgt: Tensor, std: float
) -> Tensor:
    """Transporter: source-frame features with target-frame features pasted at the keypoints.

    ``(1 - H_src)(1 - H_tgt) source + H_tgt target``, per keypoint (Kulkarni et al. 2019). Used to
    rebuild an observed frame: the keypoints learn to sit on whatever changed between the frames.

    Args:
        source: ``[N, C, H, W]`` features of the initial frame.
        target: ``[N, C, H, W]`` features of the frame to rebuild.
        pos_src: ``[N, K, 2]`` keypoints of the initial frame.
        pos_tgt: ``[N, K, 2]`` keypoints of the frame to rebuild.
        std: Blob standard deviation in ``[-1, 1]`` units.
    """
    height, width = source.shape[-2:]
    blob_tgt, keep = _blob_masks(pos_src, pos_tgt, height, width, std)
    return keep * source + blob_tgt.sum(dim=1, keepdim=True).clamp(max=1.0) * target


def shift_transport(source: Tensor, pos_src: Tensor, pos_tgt: Tensor, std: float) -> Tensor:
    """Moves source-frame features from ``pos_src`` to ``pos_tgt``: renders an unseen frame.

    Like :func:`transport`, but the features pasted under keypoint ``k``'s target blob are the
    source map shifted by ``pos_tgt[k] - pos_src[k]``, so only keypoints are needed (e.g. the
    predicted ones). With ``pos_tgt == pos_src`` the source map is returned up to blob blending.

    Args:
        source: ``[N, C, H, W]`` features of the initial frame.
        pos_src: ``[N, K, 2]`` keypoints of the initial frame.
        pos_tgt: ``[N, K, 2]`` keypoints of the frame to render.
        std: Blob standard deviation in ``[-1, 1]`` units.
    """
    n, c, h, w = source.shape
    k = pos_src.shape[1]
    blob_tgt, keep = _blob_masks(pos_src, pos_tgt, h, w, std)
    grid = pixel_grid(h, w, source.device)  # [H, W, 2]
    shift = (pos_tgt - pos_src)[:, :, None, None, :]  # [N, K, 1, 1, 2]
    sample_at = (grid - shift).reshape(n * k, h, w, 2)
    shifted = F.grid_sample(
        source.repeat_interleave(k, dim=0), sample_at, align_corners=False, padding_mode="zeros"
    ).reshape(n, k, c, h, w)
    return keep * source + (blob_tgt.unsqueeze(2) * shifted).sum(dim=1)


class KeypointReconstructor(nn.Module):
    """Reconstruction ``f_rec``: rebuilds ``I_t`` from ``I_0``'s features, ``x_0`` and ``x_t``.

    The encoder features (from :class:`KeypointDetector`) at 1/4 and 1/2 resolution are
    transported, a conv decoder upsamples the 1/4 level, joins the 1/2 level through a skip
    connection and outputs the image by a sub-pixel (pixel shuffle) convolution. The image comes
    from transported features only (never added to ``I_0``), so the decoder cannot learn a
    copy-the-input shortcut that ignores the keypoints. Training rebuilds an observed frame with
    :func:`transport` (:meth:`forward`); predicted frames, for which only keypoints exist, are
    rendered with :func:`shift_transport` (:meth:`render`).

    Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.1 and 3.4.

    Args:
        channels: ``C``, matching the detector's ``channels``.
        std: Gaussian blob standard deviation in ``[-1, 1]`` units.
    """

    def __init__(self, channels: int = 32, std: float = 0.1) -> None:
        super().__init__()
        if std <= 0:
            raise ValueError(f"std must be positive, got {std}.")
        self.std = std
        fine_ch = fine_channels(channels)
        self.up_coarse = nn.Sequential(
            _conv_block(channels, channels), nn.Upsample(scale_factor=2, mode="nearest")
        )
        self.merge = _conv_block(channels + fine_ch, fine_ch)
        # 1/2-resolution conv to 4 sub-pixels per RGB channel, then pixel shuffle to full size:
        # avoids full-resolution convolutions, the costliest part on CPU.
        self.to_rgb = nn.Sequential(nn.Conv2d(fine_ch, 12, 3, padding=1), nn.PixelShuffle(2))

    def decode(self, coarse: Tensor, fine: Tensor) -> Tensor:
        """Transported ``[N, C, H/4, W/4]`` and ``[N, C/2, H/2, W/2]`` maps -> ``[N, H, W, 3]``."""
        x = self.merge(torch.cat([self.up_coarse(coarse), fine], dim=1))
        return self.to_rgb(x).permute(0, 2, 3, 1)

    def forward(self, source: EncodedFrames, target: EncodedFrames) -> Tensor:
        """Rebuilds observed frames from the initial frames and their own encodings.

        Args:
            source: Encoded initial frames (``N`` of them).
            target: Encoded frames to rebuild (``N``).

        Returns:
            ``[N, H, W, 3]`` image in the centred network space (add 0.5 for ``[0, 1]`` RGB).
        """
        return self.decode(
            transport(source.coarse, target.coarse, source.pos, target.pos, self.std),
            transport(source.fine, target.fine, source.pos, target.pos, self.std),
        )

    def render(self, source: EncodedFrames, pos_tgt: Tensor) -> Tensor:
        """Renders the frames whose keypoints are ``pos_tgt`` ``[N, K, 2]`` (e.g. predicted ones)."""
        return self.decode(
            shift_transport(source.coarse, source.pos, pos_tgt, self.std),
            shift_transport(source.fine, source.pos, pos_tgt, self.std),
        )
