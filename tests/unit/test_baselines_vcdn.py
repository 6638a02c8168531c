"""V-CDN: keys and shapes, the inferred graph, the two training stages and what each trains,
checkpoints, and its world model (tiny untrained model, no simulation)."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from conftest import TINY_VCDN
from kinet_rl.baselines import VCDNLoss, VCDNWorldModel
from kinet_rl.envs import SceneSettings
from kinet_rl.keys import (
    ACTION,
    GOAL_KP_POS,
    GOAL_PIXELS,
    KP_EDGE_TYPE,
    KP_POS,
    PIXELS,
    PIXELS_0,
)
from kinet_rl.planners import GraphMPCPlanner, PushWorldModelEnv

K, C, SIZE = TINY_VCDN["num_keypoints"], 3, 16


@pytest.fixture
def model() -> VCDNWorldModel:
    torch.manual_seed(0)
    return VCDNWorldModel(**TINY_VCDN)


def batch(size: int = 3, horizon: int = 3) -> TensorDict:
    """Random transitions with the pushes and frames after them (as ``trainer.horizon``)."""
    gen = torch.Generator().manual_seed(0)

    def frames(*shape: int) -> torch.Tensor:
        return torch.randint(0, 256, (*shape, SIZE, SIZE, 3), dtype=torch.uint8, generator=gen)

    return TensorDict(
        {
            PIXELS_0: frames(size),
            PIXELS: frames(size),
            ACTION: torch.rand(size, 4, generator=gen) * 2 - 1,
            "next": {PIXELS: frames(size)},
            "future": {
                PIXELS: frames(size, horizon - 1),
                ACTION: torch.rand(size, horizon - 1, 4, generator=gen) * 2 - 1,
            },
        },
        batch_size=[size],
    )


def test_forward_from_pixels_writes_documented_keys(model) -> None:
    td = batch(2).select(PIXELS, ACTION)
    pixels = td[PIXELS].clone()
    out = model.eval()(td)
    expected = {
        KP_POS: (2, K, 2),
        KP_EDGE_TYPE: (2, K, K - 1, C),
        ("next", *KP_POS): (2, K, 2),
        ("next", *KP_EDGE_TYPE): (2, K, K - 1, C),
    }
    for key, shape in expected.items():
        assert out[key].shape == shape and out[key].dtype == torch.float32, key
    assert torch.equal(out[PIXELS], pixels)  # inputs are left alone
    torch.testing.assert_close(out[("next", *KP_EDGE_TYPE)], out[KP_EDGE_TYPE])  # graph carried
    with pytest.raises(KeyError, match="keypoints"):
        model(TensorDict({ACTION: torch.zeros(2, 4)}, batch_size=[2]))


def test_the_detector_sees_positions_only(model) -> None:
    assert model.detector.feat_head is None
    assert model.detector(batch(2)[PIXELS])[1].shape == (2, K, 0)


def test_inferred_edge_types_are_undirected_distributions(model) -> None:
    pos = torch.rand(5, K, 2) * 2 - 1
    types, kl = model.eval().inference(pos)
    torch.testing.assert_close(types.sum(-1), torch.ones(5, K, K - 1))
    matrix = torch.zeros(5, K, K, C)  # [receiver, sender] of each stored edge
    for k in range(K):
        senders = [i for i in range(K) if i != k]
        matrix[:, k, senders] = types[:, k]
    torch.testing.assert_close(matrix, matrix.transpose(1, 2))  # (i, k) == (k, i)
    assert kl.shape == (5,) and (kl >= -1e-6).all()  # a KL to the uniform prior
    samples, _ = model.train().inference(pos)  # Gumbel-softmax: random, still distributions
    torch.testing.assert_close(samples.sum(-1), torch.ones(5, K, K - 1))
    assert not torch.allclose(samples, types)


def test_dynamics_is_permutation_equivariant_and_needs_the_graph_of_its_keypoints(model) -> None:
    model.eval()
    pos, action = torch.rand(2, K, 2) * 2 - 1, torch.rand(2, 4) * 2 - 1
    types, _ = model.inference(pos)
    order = torch.tensor([2, 0, 3, 1])
    permuted_types, _ = model.inference(pos[:, order])
    torch.testing.assert_close(
        model.dynamics(pos, types, action)[:, order],
        model.dynamics(pos[:, order], permuted_types, action),
    )
    with pytest.raises(ValueError, match="edge_types"):
        model.dynamics(pos, types[:, :, :1], action)
    with pytest.raises(ValueError, match="action"):
        model.dynamics(pos, types, action[:, :3])


def test_rollout_keeps_the_graph_of_the_start_frame(model) -> None:
    model.eval()
    td = batch(2)
    actions = td["future", ACTION]
    kp = model.rollout_keypoints(td[PIXELS], actions)
    assert kp.shape == (2, actions.shape[1] + 1, K, 2) and not kp.requires_grad
    pos = model.keypoints(td[PIXELS])
    types, _ = model.inference(pos)
    torch.testing.assert_close(kp[:, 0], pos)
    torch.testing.assert_close(kp[:, 2], model.dynamics(kp[:, 1], types, actions[:, 1]))


def parts(model: VCDNWorldModel) -> dict[str, list[torch.nn.Parameter]]:
    perception = [*model.detector.parameters(), *model.reconstructor.parameters()]
    dynamics = [*model.inference.parameters(), *model.dynamics.parameters()]
    return {"perception": perception, "dynamics": dynamics}


def test_perception_trains_first_then_only_inference_and_dynamics(model) -> None:
    loss = VCDNLoss(model, total_steps=4, perception_fraction=0.25, rollout_weight=1.0).train()
    assert loss.perception_steps == 1 and loss.training_perception
    first = loss(batch())
    assert set(first.keys()) == {"loss_rec"} and int(loss.step) == 1
    sum(first.values()).backward()
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in parts(model)["perception"])
    assert all(p.grad is None for p in parts(model)["dynamics"])
    model.zero_grad(set_to_none=True)
    second = loss(batch())  # the perception stage is over: the detector is frozen
    assert set(second.keys()) == {"loss_fwd", "loss_kl", "loss_rollout"}
    sum(second.values()).backward()
    assert all(p.grad is None for p in parts(model)["perception"])
    for name, p in [*model.inference.named_parameters(), *model.dynamics.named_parameters()]:
        assert p.grad is not None and p.grad.abs().sum() > 0, name


def test_the_stage_counts_training_calls_only_and_is_saved_for_resuming(model) -> None:
    loss = VCDNLoss(model, total_steps=10)
    assert loss.perception_steps == 5
    with torch.no_grad():
        loss.eval()(batch())  # validation
    assert int(loss.step) == 0
    loss.train()
    for _ in range(5):
        loss(batch(size=1, horizon=1))
    assert not loss.training_perception
    resumed = VCDNLoss(VCDNWorldModel(**TINY_VCDN), total_steps=10)
    resumed.load_state_dict(loss.state_dict())
    assert int(resumed.step) == 5 and not resumed.training_perception


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        ({"total_steps": 10, "perception_fraction": 1.0}, "both stages need at least one step"),
        ({"total_steps": 10, "perception_fraction": 0.0}, "both stages need at least one step"),
        ({"total_steps": 1}, "trainer.steps >= 2"),
        ({"total_steps": 10, "kl_weight": -1.0}, "kl_weight must be >= 0"),
    ],
)
def test_bad_loss_settings_are_refused(model, arguments, message) -> None:
    with pytest.raises(ValueError, match=message):
        VCDNLoss(model, **arguments)


def test_rollout_loss_names_the_missing_future(model) -> None:
    loss = VCDNLoss(model, total_steps=2, rollout_weight=1.0).train()
    loss(batch())
    with pytest.raises(KeyError, match="trainer.horizon"):
        loss(batch().exclude("future"))


def test_bad_model_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="num_edge_types must be >= 2"):
        VCDNWorldModel(num_edge_types=1)
    with pytest.raises(ValueError, match="num_rounds must be >= 1"):
        VCDNWorldModel(num_rounds=0)


def test_checkpoint_round_trip_predicts_the_same(model, tmp_path) -> None:
    path = tmp_path / "model.pt"
    model.save_checkpoint(path, scene=SceneSettings(image_size=SIZE))
    loaded = VCDNWorldModel.from_checkpoint(path, expected_config={"num_keypoints": K}).eval()
    td = batch(2)
    torch.testing.assert_close(
        loaded.rollout_keypoints(td[PIXELS], td["future", ACTION]),
        model.eval().rollout_keypoints(td[PIXELS], td["future", ACTION]),
    )


def test_world_model_state_reward_and_planning(model) -> None:
    assert model.planning.objective == "keypoints_distance"
    world_model = model.world_model()
    env = PushWorldModelEnv(world_model)
    td = batch(2)
    observation = TensorDict({PIXELS: td[PIXELS][0], GOAL_PIXELS: td["next", PIXELS][0]}, [])
    state = world_model.observe(observation)
    assert set(state.keys(True, True)) == {KP_POS, KP_EDGE_TYPE, GOAL_KP_POS}
    assert state[KP_EDGE_TYPE].shape == (K, K - 1, C)
    torch.testing.assert_close(state[GOAL_KP_POS], model.keypoints(td["next", PIXELS][0]))
    check_env_specs(env, tensordict=env.reset(state))
    candidates = state.expand(64).clone()
    candidates[ACTION] = torch.rand(64, 4, generator=torch.Generator().manual_seed(1)) * 2 - 1
    out = env.step(candidates)
    predicted = model.dynamics(candidates[KP_POS], candidates[KP_EDGE_TYPE], candidates[ACTION])
    expected = -(predicted - candidates[GOAL_KP_POS]).norm(dim=-1).mean(-1, keepdim=True)
    torch.testing.assert_close(out["next", "reward"], expected)
    torch.testing.assert_close(out["next", KP_EDGE_TYPE], candidates[KP_EDGE_TYPE])  # carried
    planner = GraphMPCPlanner(
        env, generator=torch.Generator().manual_seed(0), num_candidates=32, top_k=4
    )
    single = state.clone()
    single[ACTION] = planner(state.clone())[ACTION]
    assert env.step(single)["next", "reward"].item() > expected.mean().item()
