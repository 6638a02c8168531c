"""Contract tests of the IN, IN-full and VisIN baselines (shapes, keys, object-count refusal,
crops)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.baselines import (
    FullStateInteractionModel,
    ObjectCountError,
    ObjectForwardLoss,
    ObjectInteractionModel,
    VisualInteractionModel,
    crop_objects,
)
from toy_pushing import ToyPushData

B, N, H = 4, 3, 32
TINY_IN = {"embed_dim": 8, "hidden_dim": 16, "num_hidden": 1, "num_rounds": 2}
TINY_VISIN = {
    **TINY_IN,
    "image_size": H,
    "crop_size": 8.0,
    "crop_resolution": 8,
    "feat_dim": 4,
    "channels": 4,
}


def batch(num_objects: int = N, seed: int = 0) -> TensorDict:
    gen = torch.Generator().manual_seed(seed)
    pos = (torch.rand(2, B, num_objects, 2, generator=gen) - 0.5) * 0.3
    return TensorDict(
        {
            "pixels": torch.randint(0, 256, (B, H, H, 3), generator=gen, dtype=torch.uint8),
            "action": torch.rand(B, 4, generator=gen) * 2 - 1,
            "object_pos": pos[0],
            "object_yaw": (torch.rand(B, num_objects, generator=gen) * 2 - 1) * torch.pi,
            "object_shape": torch.rand(B, num_objects, 8, generator=gen) * 0.04,
            "next": {"object_pos": pos[1]},
        },
        batch_size=[B],
    )


START_KEYS = ("pixels", "object_pos", "object_yaw", "object_shape")


@pytest.fixture(scope="module")
def models():
    torch.manual_seed(0)
    return [
        ObjectInteractionModel(num_objects=N, **TINY_IN),
        VisualInteractionModel(num_objects=N, **TINY_VISIN),
        FullStateInteractionModel(num_objects=N, **TINY_IN),
    ]


def test_forward_writes_next_object_pos(models):
    for model in models:
        td = batch()
        pos = td["object_pos"].clone()
        out = model(td)
        assert out[("next", "object_pos")].shape == (B, N, 2)
        assert out[("next", "object_pos")].dtype == torch.float32
        assert torch.equal(out["object_pos"], pos)


def test_loss_is_a_finite_scalar_with_gradient(models):
    for model in models:
        losses = ObjectForwardLoss(model)(batch())
        assert list(losses.keys()) == ["loss_fwd"] and losses["loss_fwd"].shape == ()
        losses["loss_fwd"].backward()
        assert any(p.grad is not None for p in model.parameters())


@pytest.mark.parametrize("count", [2, 5])
def test_refuses_another_object_count(models, count):
    for model in models:
        with pytest.raises(ObjectCountError, match=rf"num_objects=3.*has {count} objects"):
            model(batch(num_objects=count))
        start = batch(num_objects=count).select(*START_KEYS)
        with pytest.raises(ObjectCountError, match=f"num_objects={count}"):
            model.object_rollout()(start, torch.zeros(B, 2, 4))


def test_rollout_shapes(models):
    for model in models:
        pred = model.object_rollout()(batch().select(*START_KEYS), torch.rand(B, 3, 4))
        assert pred.shape == (B, 3, N, 2) and pred.dtype == torch.float32


def test_in_full_prediction_depends_on_yaw_and_shape(models):
    in_full = models[2]
    assert in_full.node_features(batch()).shape == (B, N, 10)
    td = batch()
    reference = in_full(td.clone())["next", "object_pos"]
    turned, reshaped = td.clone(), td.clone()
    turned["object_yaw"] = td["object_yaw"] + 1.0
    reshaped["object_shape"] = td["object_shape"] * 2.0
    for changed in (turned, reshaped):
        pred = in_full(changed)["next", "object_pos"]
        assert (pred - reference).abs().max() > 1e-6


def test_in_full_names_the_missing_state(models):
    with pytest.raises(KeyError, match=r"missing \['object_shape'\].*collect it again"):
        models[2](batch().exclude("object_shape"))


def test_visin_refuses_other_image_sizes(models):
    visin = models[1]
    toy = ToyPushData(num_episodes=1, episode_length=1, image_size=16)
    with pytest.raises(ValueError, match="image_size=16"):
        visin.object_rollout(toy.geometry)
    with pytest.raises(ValueError, match="32x32 images"):
        visin.node_features(
            TensorDict({"pixels": toy.pixels[:, 0], "object_pos": toy.object_pos[:, 0]}, [1])
        )


def test_crop_objects_is_centred_on_the_point():
    image = torch.zeros(1, 16, 16, 3, dtype=torch.uint8)
    image[0, 4, 10] = 255  # pixel (x=10, y=4): normalised ((10 + 0.5) / 8 - 1, (4 + 0.5) / 8 - 1)
    centre = torch.tensor([[[10.5 / 8 - 1, 4.5 / 8 - 1], [0.0, 0.0]]])
    crops = crop_objects(image, centre, crop_size=3.0, resolution=3)
    assert crops.shape == (1, 2, 3, 3, 3)
    assert crops[0, 0, 1, 1].tolist() == [1.0, 1.0, 1.0]
    assert crops[0, 0].sum() == 3.0 and crops[0, 1].sum() == 0.0


def test_crops_at_projected_positions_see_the_object_colour():
    toy = ToyPushData(num_episodes=4, episode_length=1, image_size=H)
    pos = toy.object_pos[:, 0]
    uv = toy.geometry.projection.objects_to_image(pos, toy.geometry.object_height)
    crops = crop_objects(toy.pixels[:, 0], uv, crop_size=1.0, resolution=1)
    centre = crops[:, :, 0, 0]  # [E, N, 3]
    # the last-drawn object lies on top of any overlap, so its centre shows its colour (blue)
    assert (centre[:, -1] * 255 - torch.tensor([40.0, 60.0, 220.0])).abs().max() < 2


def test_checkpoint_round_trip(models, tmp_path):
    for model in models:
        model.eval()
        path = tmp_path / f"{type(model).__name__}.pt"
        model.save_checkpoint(path)
        loaded = type(model).from_checkpoint(path, expected_config={"num_objects": N}).eval()
        td = batch()
        assert torch.equal(
            model(td.clone())[("next", "object_pos")], loaded(td.clone())[("next", "object_pos")]
        )
