"""KINet losses: contract, gradient isolation, InfoNCE on constructed cases, ablations."""

from __future__ import annotations

import math

import pytest
import torch
from tensordict import TensorDict

from kinet_rl.keys import ACTION, PIXELS, PIXELS_0
from kinet_rl.models import KINetLoss, KINetWorldModel, graph_info_nce

LOSS_NAMES = ("loss_rec", "loss_fwd", "loss_kl", "loss_ctr")


def make_model(
    deterministic: bool = False, feature_grad: str = "head", heatmap_stride: int = 4
) -> KINetWorldModel:
    torch.manual_seed(0)
    return KINetWorldModel(
        num_keypoints=3,
        feat_dim=4,
        channels=8,
        embed_dim=8,
        hidden_dim=16,
        num_hidden=1,
        num_rounds=2,
        deterministic=deterministic,
        feature_grad=feature_grad,
        heatmap_stride=heatmap_stride,
    )


def batch(size: int = 4) -> TensorDict:
    gen = torch.Generator().manual_seed(0)
    frames = torch.randint(0, 256, (3, size, 16, 16, 3), dtype=torch.uint8, generator=gen)
    return TensorDict(
        {
            PIXELS_0: frames[0],
            PIXELS: frames[1],
            ACTION: torch.rand(size, 4, generator=gen) * 2 - 1,
            "next": {PIXELS: frames[2]},
        },
        batch_size=[size],
    )


def test_losses_are_finite_float_scalars_with_gradient():
    losses = KINetLoss(make_model())(batch())
    assert set(losses.keys()) == set(LOSS_NAMES)
    for name in LOSS_NAMES:
        value = losses[name]
        assert value.shape == () and value.dtype == torch.float32, name
        assert torch.isfinite(value) and value.requires_grad, name
        assert value >= 0, name


def test_weights_scale_each_term():
    td = batch()
    defaults = {"rec_weight": 1.0, "fwd_weight": 1.0, "kl_weight": 0.01, "ctr_weight": 0.1}
    weights = {"rec_weight": 2.0, "fwd_weight": 3.0, "kl_weight": 0.5, "ctr_weight": 0.25}
    base = KINetLoss(make_model())(td)  # make_model seeds: both calls draw the same edge noise
    scaled = KINetLoss(make_model(), **weights)(td)
    for name, key in zip(LOSS_NAMES, weights, strict=True):
        ratio = weights[key] / defaults[key]
        torch.testing.assert_close(scaled[name], base[name] * ratio, rtol=1e-4, atol=1e-6)


def grad_norms(loss: torch.Tensor, module: torch.nn.Module) -> float:
    params = [p for p in module.parameters() if p.requires_grad]
    grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
    return sum(0.0 if g is None else g.abs().sum().item() for g in grads)


def without(module: torch.nn.Module, *skip: torch.nn.Module) -> torch.nn.ModuleList:
    """The submodules of ``module`` other than ``skip`` (their parameters, for grad_norms)."""
    skipped = {id(p) for m in skip for p in m.parameters()}
    rest = torch.nn.ParameterList([p for p in module.parameters() if id(p) not in skipped])
    return torch.nn.ModuleList([rest])


@pytest.mark.parametrize("heatmap_stride", [4, 2])
def test_forward_losses_train_the_features_but_never_move_the_keypoints(heatmap_stride):
    model = make_model(heatmap_stride=heatmap_stride)
    losses = KINetLoss(model, kl_weight=1.0, ctr_weight=1.0)(batch())
    detector, interaction = model.detector, model.interaction
    assert grad_norms(losses["loss_rec"], detector) > 0
    assert grad_norms(losses["loss_rec"], model.reconstructor) > 0
    assert grad_norms(losses["loss_rec"], interaction) == 0
    for name in ("loss_fwd", "loss_kl", "loss_ctr"):
        assert grad_norms(losses[name], interaction) > 0, name
        assert grad_norms(losses[name], detector.feat_head) > 0, name
        assert grad_norms(losses[name], without(detector, detector.feat_head)) == 0, name
        assert grad_norms(losses[name], model.reconstructor) == 0, name


@pytest.mark.parametrize("heatmap_stride", [4, 2])
def test_every_trainable_parameter_gets_a_gradient(heatmap_stride):
    for feature_grad in ("head", "encoder"):
        model = make_model(feature_grad=feature_grad, heatmap_stride=heatmap_stride)
        losses = KINetLoss(model, kl_weight=1.0, ctr_weight=1.0)(batch())
        sum(losses.values()).backward()
        dead = [n for n, p in model.named_parameters() if p.grad is None or not p.grad.any()]
        assert not dead, (feature_grad, heatmap_stride, dead)


def test_encoder_features_reach_the_encoder_but_not_the_heatmaps():
    model = make_model(feature_grad="encoder")
    losses = KINetLoss(model, ctr_weight=1.0)(batch())
    detector = model.detector
    assert grad_norms(losses["loss_fwd"], detector.coarse_net) > 0
    assert grad_norms(losses["loss_fwd"], detector.heatmap_head) == 0


def test_fixed_feature_ablation_keeps_forward_losses_off_the_detector():
    model = make_model(feature_grad="none")
    losses = KINetLoss(model, kl_weight=1.0, ctr_weight=1.0)(batch())
    for name in ("loss_fwd", "loss_kl", "loss_ctr"):
        assert grad_norms(losses[name], model.detector) == 0, name


def test_deterministic_ablation_has_zero_kl():
    losses = KINetLoss(make_model(deterministic=True), kl_weight=1.0)(batch())
    assert losses["loss_kl"] == 0


def test_no_ctr_ablation_skips_the_term():
    model = make_model()
    losses = KINetLoss(model, ctr_weight=0.0)(batch())
    assert losses["loss_ctr"] == 0 and not losses["loss_ctr"].requires_grad


def test_info_nce_is_low_for_matching_distinct_graphs():
    graphs = 4.0 * torch.eye(6)[:4].reshape(4, 2, 3)  # four graphs with orthogonal nodes
    loss = graph_info_nce(graphs, graphs)
    assert loss < 0.01


def test_info_nce_is_log_batch_when_all_graphs_are_equal():
    graphs = torch.randn(1, 3, 5).expand(8, 3, 5)
    torch.testing.assert_close(graph_info_nce(graphs, graphs), torch.tensor(math.log(8)))


def test_info_nce_penalises_a_mismatched_positive():
    gen = torch.Generator().manual_seed(0)
    target = 3 * torch.randn(5, 2, 4, generator=gen)
    matched = graph_info_nce(target, target)
    shuffled = graph_info_nce(target[torch.tensor([1, 2, 3, 4, 0])], target)
    assert shuffled > matched + 1.0


def test_info_nce_temperature_sharpens():
    gen = torch.Generator().manual_seed(1)
    graphs = torch.randn(4, 2, 3, generator=gen)
    assert graph_info_nce(graphs, graphs, 0.1) < graph_info_nce(graphs, graphs, 10.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"rec_weight": -1.0}, "rec_weight"), ({"ctr_temperature": 0.0}, "ctr_temperature")],
)
def test_bad_settings_are_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        KINetLoss(make_model(), **kwargs)


def test_rollout_loss_trains_the_dynamics_on_the_following_pushes():
    td = batch()
    gen = torch.Generator().manual_seed(1)
    td["future", PIXELS] = torch.randint(
        0, 256, (4, 2, 16, 16, 3), dtype=torch.uint8, generator=gen
    )
    td["future", ACTION] = torch.rand(4, 2, 4, generator=gen) * 2 - 1
    model = make_model()
    losses = KINetLoss(model, rollout_weight=1.0)(td)
    assert losses["loss_rollout"] > 0
    assert grad_norms(losses["loss_rollout"], model.interaction) > 0
    assert (
        grad_norms(losses["loss_rollout"], without(model.detector, model.detector.feat_head)) == 0
    )
    assert "loss_rollout" not in KINetLoss(make_model())(td).keys()  # noqa: SIM118
    with pytest.raises(KeyError, match="trainer.horizon > 1"):
        KINetLoss(make_model(), rollout_weight=1.0)(batch())
