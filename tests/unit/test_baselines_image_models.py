"""Contract tests of the Forw and ForwInv baselines (shapes, keys, losses, checkpoints)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.atomic import CheckpointError
from kinet_rl.baselines import ImageForwardInverseModel, ImageForwardLoss, ImageForwardModel
from kinet_rl.envs import SceneSettings
from kinet_rl.keys import IMAGE_FEAT
from kinet_rl.models.checkpointing import checkpoint_scene

B, N, H, D = 4, 3, 32, 8
TINY = {
    "feature_dim": D,
    "channels": 4,
    "num_down": 2,
    "hidden_dim": 16,
    "num_hidden": 1,
    "probe_hidden_dim": 16,
}


def batch(seed: int = 0) -> TensorDict:
    gen = torch.Generator().manual_seed(seed)
    pixels = torch.randint(0, 256, (2, B, H, H, 3), generator=gen, dtype=torch.uint8)
    pos = (torch.rand(2, B, N, 2, generator=gen) - 0.5) * 0.3
    return TensorDict(
        {
            "pixels": pixels[0],
            "pixels_0": pixels[0],
            "action": torch.rand(B, 4, generator=gen) * 2 - 1,
            "object_pos": pos[0],
            "next": {"pixels": pixels[1], "object_pos": pos[1]},
        },
        batch_size=[B],
    )


@pytest.mark.parametrize("cls", [ImageForwardModel, ImageForwardInverseModel])
def test_forward_writes_features_and_keeps_inputs(cls):
    torch.manual_seed(0)
    model = cls(**TINY)
    td = batch()
    pixels = td["pixels"].clone()
    out = model(td.select("pixels", "action"))
    assert out[IMAGE_FEAT].shape == (B, D) and out[IMAGE_FEAT].dtype == torch.float32
    assert out[("next", *IMAGE_FEAT)].shape == (B, D)
    assert torch.equal(td["pixels"], pixels)
    # LayerNorm features: zero mean, unit variance per sample (no collapse to a point possible)
    assert torch.allclose(out[IMAGE_FEAT].mean(-1), torch.zeros(B), atol=1e-5)


def test_losses_keys_and_probe_is_detached():
    torch.manual_seed(0)
    model = ImageForwardInverseModel(**TINY)
    loss = ImageForwardLoss(model, inv_weight=1.0)
    losses = loss(batch())
    assert set(losses.keys()) == {"loss_fwd", "loss_ctr", "loss_inv", "loss_probe"}
    assert all(v.shape == () and torch.isfinite(v) for v in losses.values())
    losses["loss_probe"].backward()
    assert all(p.grad is None for p in model.encoder.parameters())
    assert all(p.grad is not None for p in model.probe.parameters())


def test_forw_loss_has_no_inverse_term_and_rejects_inv_weight():
    model = ImageForwardModel(**TINY)
    assert "loss_inv" not in ImageForwardLoss(model)(batch())
    with pytest.raises(ValueError, match="model=forwinv"):
        ImageForwardLoss(model, inv_weight=1.0)
    with pytest.raises(ValueError, match="ctr_weight must be >= 0"):
        ImageForwardLoss(model, ctr_weight=-1.0)


def test_loss_names_missing_keys():
    with pytest.raises(KeyError, match="missing"):
        ImageForwardLoss(ImageForwardModel(**TINY))(batch().exclude(("next", "object_pos")))


def test_object_rollout_shapes_and_start():
    torch.manual_seed(0)
    model = ImageForwardModel(**TINY).eval()
    td = batch()
    actions = torch.rand(B, 5, 4) * 2 - 1
    pred = model.object_rollout()(td.select("pixels", "pixels_0", "object_pos"), actions)
    assert pred.shape == (B, 5, N, 2) and pred.dtype == torch.float32
    # one-step prediction = start + probe motion between the start and predicted features
    feat = model.encode(td["pixels"])
    expected = td["object_pos"] + model.probe_motion(
        feat, model.predict(feat, actions[:, 0]), td["object_pos"]
    )
    assert torch.allclose(pred[:, 0], expected, atol=1e-6)


def test_checkpoint_round_trip_and_refusals(tmp_path):
    torch.manual_seed(0)
    model = ImageForwardInverseModel(**TINY).eval()
    path = tmp_path / "forwinv.pt"
    scene = SceneSettings(image_size=H)
    model.save_checkpoint(path, scene=scene)
    assert checkpoint_scene(path) == scene
    loaded = ImageForwardInverseModel.from_checkpoint(
        path, expected_config={"feature_dim": D}
    ).eval()
    td = batch()
    assert torch.equal(
        model(td.clone())[("next", *IMAGE_FEAT)], loaded(td.clone())[("next", *IMAGE_FEAT)]
    )
    with pytest.raises(CheckpointError, match="ImageForwardInverseModel"):
        ImageForwardModel.from_checkpoint(path)
    with pytest.raises(CheckpointError, match="feature_dim: expected 9"):
        ImageForwardInverseModel.from_checkpoint(path, expected_config={"feature_dim": 9})
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        ImageForwardModel.from_checkpoint(tmp_path / "bad.pt")
