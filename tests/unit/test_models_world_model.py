"""KINetWorldModel: TensorDict contract, transition outputs, checkpoint round trip and refusals."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.atomic import CheckpointError
from kinet_rl.envs import SceneSettings
from kinet_rl.keys import ACTION, KP_FEAT, KP_NODE_EMB, KP_POS, PIXELS, PIXELS_0
from kinet_rl.models import KINetWorldModel
from kinet_rl.models.checkpointing import checkpoint_scene

CONFIG = {
    "num_keypoints": 3,
    "feat_dim": 4,
    "channels": 8,
    "blob_std": 0.1,
    "embed_dim": 8,
    "hidden_dim": 16,
    "num_hidden": 1,
    "num_rounds": 2,
    "deterministic": False,
}
SIZE = 16


@pytest.fixture
def model() -> KINetWorldModel:
    torch.manual_seed(0)
    return KINetWorldModel(**CONFIG)


def transitions(batch: int = 2) -> TensorDict:
    gen = torch.Generator().manual_seed(0)

    def frames() -> torch.Tensor:
        return torch.randint(0, 256, (batch, SIZE, SIZE, 3), dtype=torch.uint8, generator=gen)

    return TensorDict(
        {
            PIXELS_0: frames(),
            PIXELS: frames(),
            ACTION: torch.rand(batch, 4, generator=gen) * 2 - 1,
            "next": {PIXELS: frames()},
        },
        batch_size=[batch],
    )


def test_forward_from_pixels_writes_documented_keys(model):
    td = transitions(batch=2).exclude(PIXELS_0, "next")
    pixels = td[PIXELS].clone()
    out = model(td)
    k, d, e = CONFIG["num_keypoints"], CONFIG["feat_dim"], CONFIG["embed_dim"]
    expected = {
        KP_POS: (2, k, 2),
        KP_FEAT: (2, k, d),
        KP_NODE_EMB: (2, k, e),
        ("next", *KP_POS): (2, k, 2),
        ("next", *KP_FEAT): (2, k, d),
        ("next", *KP_NODE_EMB): (2, k, e),
    }
    for key, shape in expected.items():
        assert out[key].shape == shape and out[key].dtype == torch.float32, key
    assert torch.equal(out[PIXELS], pixels)  # inputs are left alone
    torch.testing.assert_close(out[("next", *KP_FEAT)], out[KP_FEAT])  # appearance carried over


def test_forward_from_keypoints_needs_no_pixels_and_any_k(model):
    model.eval()
    td = TensorDict(
        {KP_POS: torch.zeros(4, 7, 2), KP_FEAT: torch.zeros(4, 7, 4), ACTION: torch.zeros(4, 4)},
        batch_size=[4],
    )
    out = model(td)
    assert out[("next", *KP_POS)].shape == (4, 7, 2)


def test_forward_without_inputs_names_the_fix(model):
    td = TensorDict({ACTION: torch.zeros(2, 4)}, batch_size=[2])
    with pytest.raises(KeyError, match="KeypointTransform"):
        model(td)


def test_transition_outputs(model):
    out = model.transition(transitions(batch=3))
    k, d = CONFIG["num_keypoints"], CONFIG["feat_dim"]
    assert out.pos.shape == out.next_pos.shape == (3, k, 2)
    assert out.next_feat.shape == (3, k, d)
    assert out.reconstruction.shape == out.target.shape == (3, SIZE, SIZE, 3)
    assert out.target.min() >= -0.5 and out.target.max() <= 0.5
    assert out.prediction.next_pos.shape == (3, k, 2)
    assert out.pos.requires_grad and not out.next_pos.requires_grad  # x_t+1 is only a target
    # The frames of one transition are encoded by the detector's own weights.
    td = transitions(batch=3)
    torch.testing.assert_close(out.pos, model.detector(td[PIXELS])[0])
    torch.testing.assert_close(out.next_pos, model.detector(td["next", PIXELS])[0])


def test_transition_names_missing_and_mismatched_inputs(model):
    with pytest.raises(KeyError, match="pixels_0"):
        model.transition(transitions().exclude(PIXELS_0))
    td = transitions()
    td.set(PIXELS_0, torch.zeros(2, 8, 8, 3, dtype=torch.uint8))
    with pytest.raises(ValueError, match="share one"):
        model.transition(td)


def test_predict_pixels_range_and_no_grad(model):
    td = transitions()
    pos, _ = model.detector(td[PIXELS])
    image = model.predict_pixels(td[PIXELS_0], pos)
    assert image.shape == (2, SIZE, SIZE, 3) and not image.requires_grad
    assert image.min() >= 0 and image.max() <= 1


def test_checkpoint_round_trip(model, tmp_path):
    path = tmp_path / "ckpt" / "model.pt"
    scene = SceneSettings(task="ycb", camera="side", image_size=SIZE)
    model.save_checkpoint(path, scene=scene)
    loaded = KINetWorldModel.from_checkpoint(path, expected_config={"num_keypoints": 3})
    assert checkpoint_scene(path) == scene
    assert loaded.config == model.config
    for (name, a), (_, b) in zip(
        model.state_dict().items(), loaded.state_dict().items(), strict=True
    ):
        assert torch.equal(a, b), name
    assert not list(path.parent.glob(".*tmp"))  # atomic write leaves no temporary file


def test_half_resolution_heatmaps_survive_a_checkpoint_and_old_files_load_as_stride_4(tmp_path):
    torch.manual_seed(0)
    model = KINetWorldModel(**CONFIG, heatmap_stride=2).eval()
    model.save_checkpoint(tmp_path / "half.pt")
    loaded = KINetWorldModel.from_checkpoint(tmp_path / "half.pt").eval()
    pixels = transitions()[PIXELS]
    assert loaded.detector.heatmap_stride == 2
    torch.testing.assert_close(loaded.detector(pixels), model.detector(pixels))
    old = KINetWorldModel(**CONFIG)
    del old.config["heatmap_stride"]  # a file written before the option existed
    old.save_checkpoint(tmp_path / "old.pt")
    assert KINetWorldModel.from_checkpoint(tmp_path / "old.pt").detector.heatmap_stride == 4


def test_checkpoint_truncated_or_corrupt_file_is_refused(model, tmp_path):
    path = tmp_path / "model.pt"
    model.save_checkpoint(path)
    assert checkpoint_scene(path) is None  # saved without a scene
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        KINetWorldModel.from_checkpoint(path)
    path.write_bytes(b"not a checkpoint" * 10)
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        KINetWorldModel.from_checkpoint(path)
    with pytest.raises(CheckpointError, match="No checkpoint file"):
        KINetWorldModel.from_checkpoint(tmp_path / "missing.pt")


def test_checkpoint_mismatched_config_is_refused(model, tmp_path):
    path = tmp_path / "model.pt"
    model.save_checkpoint(path)
    with pytest.raises(CheckpointError, match="num_keypoints: expected 6, checkpoint 3"):
        KINetWorldModel.from_checkpoint(path, expected_config={"num_keypoints": 6})


def test_checkpoint_foreign_or_edited_file_is_refused(model, tmp_path):
    path = tmp_path / "model.pt"
    torch.save({"weights": model.state_dict()}, path)
    with pytest.raises(CheckpointError, match="not written by"):
        KINetWorldModel.from_checkpoint(path)
    state = {
        "format": "kinet_rl.KINetWorldModel/1",
        "model_config": {**CONFIG, "channels": 16},
        "scene": None,
        "state_dict": model.state_dict(),
    }
    torch.save(state, path)
    with pytest.raises(CheckpointError, match="do not fit its model config"):
        KINetWorldModel.from_checkpoint(path)
    torch.save({**state, "format": "other/2"}, path)
    with pytest.raises(CheckpointError, match="has format"):
        KINetWorldModel.from_checkpoint(path)


class _Foreign:
    """A pickled object that ``weights_only=True`` refuses to build."""


def test_a_checkpoint_with_code_is_refused_without_advice_to_run_it(tmp_path) -> None:
    path = tmp_path / "hostile.pt"
    torch.save({"format": "x", "payload": _Foreign()}, path)
    with pytest.raises(CheckpointError, match="cannot be loaded safely") as info:
        KINetWorldModel.from_checkpoint(path)
    text = str(info.value)
    assert str(path) in text and "weights_only=True" in text
    assert "weights_only=False" not in text and "set to `False`" not in text
    assert info.value.__cause__ is None  # torch's own advice is not chained either


def test_a_corrupt_checkpoint_error_names_the_file_and_gives_no_unsafe_advice(tmp_path) -> None:
    path = tmp_path / "garbage.pt"
    path.write_bytes(b"not a checkpoint" * 10)
    with pytest.raises(
        CheckpointError, match="corrupt or truncated and could not be read safely"
    ) as info:
        KINetWorldModel.from_checkpoint(path)
    assert str(path) in str(info.value) and "delete it" in str(info.value)
    assert "weights_only=False" not in str(info.value) and info.value.__cause__ is None
