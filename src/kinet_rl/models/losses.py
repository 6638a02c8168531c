"""KINet training losses: reconstruction, forward, edge inference (KL) and graph contrastive.

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 3.5.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from tensordict import TensorDict, TensorDictBase
from torch import Tensor
from torchrl.objectives import LossModule

from kinet_rl.keys import EPISODE, FUTURE_ACTION, FUTURE_PIXELS
from kinet_rl.models.interaction import graph_similarity
from kinet_rl.models.world_model import KINetWorldModel


def check_loss_weights(ctr_temperature: float = 1.0, **weights: float) -> None:
    """Raise a ValueError naming a negative loss weight or a non-positive contrastive temperature."""
    for name, value in weights.items():
        if value < 0:
            raise ValueError(f"{name} must be >= 0, got {value}.")
    if ctr_temperature <= 0:
        raise ValueError(f"ctr_temperature must be > 0, got {ctr_temperature}.")


def keypoint_error(predicted: Tensor, target: Tensor) -> Tensor:
    """The forward loss on keypoints: ``sum_k |x_hat_k - x_k|^2``, averaged over leading dims.

    Args:
        predicted: ``[*B, K, 2]`` predicted keypoints (e.g. ``[B, H, K, 2]`` over a rollout).
        target: ``[*B, K, 2]`` detected keypoints (pass them detached).
    """
    return (predicted - target).pow(2).sum(dim=(-2, -1)).mean()


#: Logits of the contrastive loss between two graphs (see :func:`graph_logits`).
CTR_SIMILARITIES = ("dot", "cosine", "distance")
#: Where the contrastive loss takes its negatives from.
CTR_NEGATIVES = ("batch", "episode")


def graph_logits(predicted: Tensor, target: Tensor, similarity: str = "dot") -> Tensor:
    """Similarity of every predicted graph with every target graph, ``[B, K, E] x [B, K, E] -> [B, B]``.

    ``"dot"``: the paper's ``S(G1, G2) = sum_k n1_k . n2_k`` (unbounded: it rewards growing
    norms). ``"cosine"``: the cosine of the two flattened ``[K * E]`` graphs, in ``[-1, 1]``.
    ``"distance"``: minus the mean over nodes of ``|n1_k - n2_k|^2``, maximal only at a match.
    """
    if similarity == "dot":
        return graph_similarity(predicted.unsqueeze(1), target.unsqueeze(0))
    if similarity == "cosine":
        a = F.normalize(predicted.flatten(-2), dim=-1)
        b = F.normalize(target.flatten(-2), dim=-1)
        return a @ b.T
    if similarity == "distance":
        diff = predicted.unsqueeze(1) - target.unsqueeze(0)  # [B, B, K, E]
        return -diff.pow(2).sum(-1).mean(-1)
    raise ValueError(f"similarity={similarity!r}; choose one of {CTR_SIMILARITIES}.")


def graph_info_nce(
    predicted: Tensor,
    target: Tensor,
    temperature: float = 1.0,
    similarity: str = "dot",
    groups: Tensor | None = None,
) -> Tensor:
    """InfoNCE over a batch of graphs with :func:`graph_logits` ``/ temperature`` as logits.

    Sample ``b``'s positive is ``target[b]``; its negatives are the other targets of the batch or,
    with ``groups``, only those of the same group (e.g. other timesteps of the same episode: the
    paper's ``G_tau, tau != t+1``). A sample whose group holds no other sample is left out.

    Args:
        predicted: ``[B, K, E]`` predicted node embeddings.
        target: ``[B, K, E]`` node embeddings of the true next graphs.
        temperature: Divides the logits.
        similarity: ``"dot"``, ``"cosine"`` or ``"distance"`` (:func:`graph_logits`).
        groups: Optional ``[B]`` group id of each sample.

    Returns:
        Scalar mean cross-entropy (0 when no sample has a negative).
    """
    logits = graph_logits(predicted, target, similarity) / temperature  # [B, B]
    labels = torch.arange(predicted.shape[0], device=predicted.device)
    if groups is None:
        return F.cross_entropy(logits, labels)
    same = groups.unsqueeze(0) == groups.unsqueeze(1)
    logits = logits.masked_fill(~same, float("-inf"))
    counted = same.sum(-1) > 1
    if not counted.any():
        return logits.new_zeros(())
    return F.cross_entropy(logits[counted], labels[counted])


class KINetLoss(LossModule):
    """Weighted KINet losses for a batch of transitions.

    ``loss_rec``: mean squared error of ``f_rec`` rebuilding ``I_t`` from ``I_0`` and the detected
    keypoints (trains detector and reconstructor). ``loss_fwd``: mean over
    the batch of ``sum_k |x_hat_t+1 - f_kp(I_t+1)|^2`` with a detached target. ``loss_kl``: mean
    edge KL to the prior. ``loss_ctr``: :func:`graph_info_nce` between predicted next node
    embeddings and the node embeddings of the detected (detached) next graph, with negatives from
    the batch or from other timesteps of the same episode (``ctr_negatives``). Each entry is
    already multiplied by its weight, so the total loss is their sum.

    Keys:
        Reads a ``[B]`` batch with ``"pixels_0"``, ``"pixels"`` (uint8 ``[B, H, W, 3]``),
        ``"action"`` ``[B, 4]``, ``("next", "pixels")`` and, for ``ctr_negatives="episode"``,
        ``"episode"`` ``[B]`` (sample batches with several steps per episode:
        ``PushDataset.sample(..., steps_per_episode=...)``). Returns a TensorDict of scalars
        ``loss_rec``, ``loss_fwd``, ``loss_kl``, ``loss_ctr``.

    Args:
        world_model: The model being trained.
        rec_weight: ``lambda_rec``.
        fwd_weight: ``lambda_fwd``.
        kl_weight: ``lambda_infer``.
        ctr_weight: ``lambda_ctr``; 0 gives the KINet-no-ctr ablation (the term is then skipped).
        ctr_temperature: Temperature of the contrastive logits.
        ctr_similarity: Contrastive logits: ``"dot"`` (the paper's ``S``), ``"cosine"`` or
            ``"distance"`` (see :func:`graph_logits`).
        ctr_negatives: ``"batch"`` (other samples of the batch) or ``"episode"`` (other timesteps
            of the same episode, as in the paper).
        rollout_weight: Weight of ``loss_rollout``: the forward loss of the open-loop keypoint
            rollout over the pushes that follow each transition (0: off; needs batches sampled
            with ``trainer.horizon > 1``).
    """

    def __init__(
        self,
        world_model: KINetWorldModel,
        rec_weight: float = 1.0,
        fwd_weight: float = 1.0,
        kl_weight: float = 0.01,
        ctr_weight: float = 0.1,
        ctr_temperature: float = 1.0,
        ctr_similarity: str = "dot",
        ctr_negatives: str = "batch",
        rollout_weight: float = 0.0,
    ) -> None:
        super().__init__()
        if ctr_similarity not in CTR_SIMILARITIES:
            raise ValueError(
                f"ctr_similarity={ctr_similarity!r}; choose one of {CTR_SIMILARITIES}."
            )
        if ctr_negatives not in CTR_NEGATIVES:
            raise ValueError(f"ctr_negatives={ctr_negatives!r}; choose one of {CTR_NEGATIVES}.")
        check_loss_weights(
            ctr_temperature,
            rec_weight=rec_weight,
            fwd_weight=fwd_weight,
            kl_weight=kl_weight,
            ctr_weight=ctr_weight,
            rollout_weight=rollout_weight,
        )
        self.world_model = world_model
        self.rec_weight = rec_weight
        self.fwd_weight = fwd_weight
        self.kl_weight = kl_weight
        self.ctr_weight = ctr_weight
        self.ctr_temperature = ctr_temperature
        self.ctr_similarity = ctr_similarity
        self.ctr_negatives = ctr_negatives
        self.rollout_weight = rollout_weight

    def forward(self, tensordict: TensorDictBase) -> TensorDict:
        """Computes the weighted losses (see class docstring)."""
        out = self.world_model.transition(tensordict)
        pred = out.prediction
        loss_rec = (out.reconstruction - out.target).pow(2).mean()
        loss_fwd = keypoint_error(pred.next_pos, out.next_pos.detach())
        loss_kl = pred.kl.mean()
        if self.ctr_weight > 0:
            target_nodes = self.world_model.interaction.embed_nodes(
                out.next_pos.detach(), out.next_feat.detach()
            )
            groups = None
            if self.ctr_negatives == "episode":
                groups = tensordict.get(EPISODE, None)
                if groups is None:
                    raise KeyError(
                        f"ctr_negatives='episode' needs the {EPISODE!r} of each transition; sample "
                        "batches with PushDataset.sample() (trainer.steps_per_episode > 1)."
                    )
            loss_ctr = graph_info_nce(
                pred.next_nodes, target_nodes, self.ctr_temperature, self.ctr_similarity, groups
            )
        else:
            loss_ctr = loss_rec.new_zeros(())
        losses = {
            "loss_rec": self.rec_weight * loss_rec,
            "loss_fwd": self.fwd_weight * loss_fwd,
            "loss_kl": self.kl_weight * loss_kl,
            "loss_ctr": self.ctr_weight * loss_ctr,
        }
        if self.rollout_weight > 0:
            if out.rollout is None or out.rollout_target is None:
                raise KeyError(
                    f"rollout_weight > 0 needs the pushes after each transition ({FUTURE_PIXELS!r}, "
                    f"{FUTURE_ACTION!r}); sample batches with trainer.horizon > 1."
                )
            error = keypoint_error(out.rollout, out.rollout_target)  # mean over B and H - 1
            losses["loss_rollout"] = self.rollout_weight * error
        return TensorDict(losses, batch_size=[])
