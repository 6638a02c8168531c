"""IN, IN-full and VisIN: interaction networks over a fixed, known set of ground-truth objects.

All build a fully connected graph with one node per object, run ``L`` rounds of
action-conditioned message passing and predict each object's displacement (the deterministic
:class:`~kinet_rl.models.interaction.KeypointInteractionNet`, fed object positions instead of
keypoints). Positions are expressed in workspace units (``xy / half_size``), the frame of the push
action, so the push's start and end relative to each object are exact.

IN's node state is the ground-truth position. Its velocity is left out: every recorded frame is
taken after the scene has settled (objects at rest), so the velocity is identically zero there.
IN-full's node state is the full ground-truth state: the position plus the yaw (as cos, sin) and
the body-frame block geometry (``OBJECT_SHAPE``, two boxes, in workspace units); it predicts
positions only, so in a rollout the start frame's yaw and shape are carried over.
VisIN's node state is the position plus visual features of a fixed-size crop centred on the
object's ground-truth position in the image; in a rollout, the start frame's crop features are
carried over (no future images exist).

Reference: KINet, Rezazadeh et al., RA-L 2023, Sec. 4 (Baselines); Battaglia et al., NeurIPS
2016; Sanchez-Gonzalez et al., ICML 2018; Watters et al., NeurIPS 2017.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import torch
from tensordict import TensorDictBase
from torch import Tensor, nn

from kinet_rl.baselines.encoders import ConvEncoder, crop_objects
from kinet_rl.baselines.imagination import object_world_model
from kinet_rl.devices import model_device
from kinet_rl.envs.geometry import (
    OBJECT_CENTRE_HEIGHT,
    CameraProjection,
    SceneGeometry,
    camera_projection,
)
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import (
    ACTION,
    GOAL_OBJECT_POS,
    NEXT_OBJECT_POS,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
    PIXELS,
)
from kinet_rl.models.checkpointing import ConfigCheckpointMixin
from kinet_rl.models.interaction import KeypointInteractionNet
from kinet_rl.planners.world_model import (
    ModelCapabilities,
    PlanningDefaults,
    PushWorldModel,
    check_objective,
)


@lru_cache(maxsize=8)
def task_camera(task: str, camera: str) -> CameraProjection:
    """:func:`camera_projection`, built once per ``(task, camera)`` (it builds a MuJoCo scene)."""
    return camera_projection(task, camera)


class ObjectCountError(ValueError):
    """A scene holds another number of objects than an object-level model was built for."""


class ObjectInteractionModel(ConfigCheckpointMixin, nn.Module):
    """IN baseline: interaction network on ground-truth object positions, action-conditioned.

    Keys:
        :meth:`forward` reads ``OBJECT_POS`` ``[*B, N, 2]`` (metres) and ``ACTION`` ``[*B, 4]``;
        writes the prediction ``("next", OBJECT_POS)`` ``[*B, N, 2]`` (metres).

    Args:
        num_objects: ``N``, the fixed object count of every scene (training and test).
        task: ``"blocks"`` or ``"ycb"``; its workspace half-size maps metres to action units.
        embed_dim: ``E`` of node and edge embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP.
        num_rounds: ``L`` message-passing rounds.
    """

    checkpoint_format = "kinet_rl.ObjectInteractionModel/1"
    label = "IN"
    #: Size of the per-object node feature (none for IN).
    node_feature_dim = 0
    #: Entries of a state that :meth:`node_features` reads besides ``OBJECT_POS`` and ``PIXELS``
    #: (observed by the env, stored by the dataset; planning hands them over).
    state_keys: tuple[str, ...] = ()
    capabilities = ModelCapabilities(
        observes=(OBJECT_POS,), goal=(GOAL_OBJECT_POS,), objectives=("object_distance",)
    )
    planning = PlanningDefaults("object_distance")

    def __init__(
        self,
        num_objects: int = 3,
        task: str = "blocks",
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
    ) -> None:
        super().__init__()
        if num_objects < 1:
            raise ValueError(f"num_objects must be >= 1, got {num_objects}.")
        self.config: dict[str, Any] = {
            "num_objects": num_objects,
            "task": task,
            "embed_dim": embed_dim,
            "hidden_dim": hidden_dim,
            "num_hidden": num_hidden,
            "num_rounds": num_rounds,
        }
        self.num_objects = num_objects
        self.position_scale = workspace_for(task).half_size
        self.interaction = KeypointInteractionNet(
            self.node_feature_dim, embed_dim, hidden_dim, num_hidden, num_rounds, deterministic=True
        )

    def check_objects(self, object_pos: Tensor) -> None:
        """Raises :class:`ObjectCountError` unless ``object_pos`` is ``[*B, num_objects, 2]``."""
        if object_pos.dim() < 2 or object_pos.shape[-1] != 2:
            raise ValueError(
                f"object_pos must be [*B, N, 2] metres, got {tuple(object_pos.shape)}."
            )
        if object_pos.shape[-2] != self.num_objects:
            raise ObjectCountError(
                f"{type(self).__name__} was trained for num_objects={self.num_objects}, but this "
                f"scene has {object_pos.shape[-2]} objects. Object-level baselines need a fixed, "
                f"known object count: evaluate on {self.num_objects}-object data or train a model "
                f"with num_objects={object_pos.shape[-2]} (KINet handles any count)."
            )

    def node_features(self, state: TensorDictBase) -> Tensor:
        """Per-object features ``[*B, N, F]`` of a state with ``OBJECT_POS`` (IN: ``F = 0``)."""
        object_pos = state.get(OBJECT_POS)
        return object_pos.new_zeros(*object_pos.shape[:-1], 0)

    def predict(self, object_pos: Tensor, node_feat: Tensor, action: Tensor) -> Tensor:
        """Next object positions ``[*B, N, 2]`` metres after push ``action`` ``[*B, 4]``.

        Args:
            object_pos: ``[*B, N, 2]`` metres.
            node_feat: ``[*B, N, F]`` from :meth:`node_features`.
            action: ``[*B, 4]`` push in workspace units.
        """
        self.check_objects(object_pos)
        pos = object_pos / self.position_scale
        return self.interaction(pos, node_feat, action).next_pos * self.position_scale

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Predicts ``("next", OBJECT_POS)`` (see the class ``Keys:``)."""
        next_pos = self.predict(
            tensordict.get(OBJECT_POS), self.node_features(tensordict), tensordict.get(ACTION)
        )
        tensordict.set(NEXT_OBJECT_POS, next_pos)
        return tensordict

    def object_rollout(self, geometry: SceneGeometry | None = None) -> ObjectStateRollout:
        """The :class:`~kinet_rl.evaluation.forward.ObjectRollout` of this model.

        IN works on the table in metres and needs no ``geometry``.
        """
        return ObjectStateRollout(self)

    def world_model(self, objective: str | None = None) -> PushWorldModel:
        """This model as a ``torchrl.modules.WorldModel`` on ground-truth object positions
        (:func:`~kinet_rl.baselines.imagination.object_world_model`)."""
        name = check_objective(self.capabilities, objective or self.planning.objective, self.label)
        return object_world_model(self, name)


class VisualInteractionModel(ObjectInteractionModel):
    """VisIN baseline: IN whose nodes also carry conv features of a crop around each object.

    Crops of ``crop_size`` image pixels are centred on each object's ground-truth position
    projected into the image with the task camera (:func:`task_camera`, at the task's
    object-centre height) and resampled to ``crop_resolution`` squared samples.

    Keys:
        :meth:`forward` reads ``PIXELS`` ``[*B, H, W, 3]``, ``OBJECT_POS`` ``[*B, N, 2]`` and
        ``ACTION`` ``[*B, 4]``; writes ``("next", OBJECT_POS)`` ``[*B, N, 2]`` (metres).

    Args:
        num_objects: ``N``, the fixed object count of every scene.
        task: ``"blocks"`` or ``"ycb"`` (workspace, camera and object-centre height).
        camera: ``"top"`` or ``"side"``, the camera of the images.
        image_size: Side of the images in pixels.
        crop_size: Side of each object crop in image pixels.
        crop_resolution: Side of each resampled crop.
        feat_dim: ``F`` of each object's visual feature.
        channels: Width of the crop encoder.
        embed_dim: ``E`` of node and edge embeddings.
        hidden_dim: Hidden units of every MLP.
        num_hidden: Hidden layers of every MLP.
        num_rounds: ``L`` message-passing rounds.
    """

    checkpoint_format = "kinet_rl.VisualInteractionModel/1"
    label = "VisIN"
    capabilities = ModelCapabilities(
        observes=(PIXELS, OBJECT_POS), goal=(GOAL_OBJECT_POS,), objectives=("object_distance",)
    )
    camera_position: Tensor  # [3] buffer
    camera_rotation: Tensor  # [3, 3] buffer

    def __init__(
        self,
        num_objects: int = 3,
        task: str = "blocks",
        camera: str = "top",
        image_size: int = 64,
        crop_size: float = 16.0,
        crop_resolution: int = 16,
        feat_dim: int = 16,
        channels: int = 32,
        embed_dim: int = 64,
        hidden_dim: int = 128,
        num_hidden: int = 3,
        num_rounds: int = 3,
    ) -> None:
        if crop_size <= 0 or crop_resolution < 4:
            raise ValueError(
                f"crop_size must be > 0 and crop_resolution >= 4, got {crop_size}, {crop_resolution}."
            )
        self.node_feature_dim = feat_dim
        super().__init__(num_objects, task, embed_dim, hidden_dim, num_hidden, num_rounds)
        self.config.update(
            {
                "camera": camera,
                "image_size": image_size,
                "crop_size": crop_size,
                "crop_resolution": crop_resolution,
                "feat_dim": feat_dim,
                "channels": channels,
            }
        )
        self.image_size = image_size
        self.crop_size = crop_size
        self.crop_resolution = crop_resolution
        projection = task_camera(task, camera)
        self.register_buffer("camera_position", projection.position.clone(), persistent=False)
        self.register_buffer("camera_rotation", projection.rotation.clone(), persistent=False)
        self.tan_half_fovy = projection.tan_half_fovy
        self.object_height = OBJECT_CENTRE_HEIGHT[task]
        num_down = max(1, (crop_resolution // 4).bit_length() - 1)  # down to about 4 x 4
        self.crop_encoder = ConvEncoder(feat_dim, channels, num_down)

    def node_features(self, state: TensorDictBase) -> Tensor:
        """Crop features ``[B, N, F]`` of ``PIXELS`` ``[B, H, W, 3]`` at ``OBJECT_POS``."""
        pixels, object_pos = state.get(PIXELS), state.get(OBJECT_POS)
        self.check_objects(object_pos)
        if pixels.dim() != 4 or pixels.shape[-3:] != (self.image_size, self.image_size, 3):
            raise ValueError(
                f"{type(self).__name__} was built for {self.image_size}x{self.image_size} images "
                f"[B, H, W, 3], got {tuple(pixels.shape)}; set image_size to the data's env.image_size."
            )
        projection = CameraProjection(
            self.camera_position, self.camera_rotation, self.tan_half_fovy
        )
        centres = projection.objects_to_image(object_pos, self.object_height)
        crops = crop_objects(pixels, centres, self.crop_size, self.crop_resolution)
        return self.crop_encoder(crops)

    def object_rollout(self, geometry: SceneGeometry | None = None) -> ObjectStateRollout:
        """The :class:`~kinet_rl.evaluation.forward.ObjectRollout` of this model.

        Raises:
            ValueError: ``geometry`` has another image size than the model.
        """
        if geometry is not None and geometry.image_size != self.image_size:
            raise ValueError(
                f"{type(self).__name__} crops {self.image_size}-pixel images but the evaluation "
                f"geometry has image_size={geometry.image_size}; evaluate on data of the training size."
            )
        return ObjectStateRollout(self)


class FullStateInteractionModel(ObjectInteractionModel):
    """IN-full baseline: IN whose nodes also carry each object's yaw and block geometry.

    Node features: ``cos(yaw)``, ``sin(yaw)`` and the 8 numbers of ``OBJECT_SHAPE`` divided by
    the workspace half-size. It predicts positions only: in a multi-push rollout
    (:class:`ObjectStateRollout`) the start frame's yaw and shape are carried over.

    Keys:
        :meth:`forward` reads ``OBJECT_POS`` ``[*B, N, 2]`` (metres), ``OBJECT_YAW`` ``[*B, N]``
        (radians), ``OBJECT_SHAPE`` ``[*B, N, 8]`` (metres) and ``ACTION`` ``[*B, 4]``; writes
        ``("next", OBJECT_POS)`` ``[*B, N, 2]`` (metres).

    Args: as :class:`ObjectInteractionModel`.
    """

    checkpoint_format = "kinet_rl.FullStateInteractionModel/1"
    label = "IN-full"
    node_feature_dim = 10
    state_keys = (OBJECT_YAW, OBJECT_SHAPE)
    capabilities = ModelCapabilities(
        observes=(OBJECT_POS, OBJECT_YAW, OBJECT_SHAPE),
        goal=(GOAL_OBJECT_POS,),
        objectives=("object_distance",),
    )

    def node_features(self, state: TensorDictBase) -> Tensor:
        """``[*B, N, 10]``: cos and sin of ``OBJECT_YAW``, ``OBJECT_SHAPE`` in workspace units."""
        missing = [key for key in self.state_keys if state.get(key, None) is None]
        if missing:
            raise KeyError(
                f"{type(self).__name__} (IN-full) needs {list(self.state_keys)} in its input, "
                f"missing {missing}. Datasets collected by an older kinet_rl lack object_shape: "
                "delete the dataset folder and collect it again."
            )
        yaw, shape = state.get(OBJECT_YAW), state.get(OBJECT_SHAPE)
        self.check_objects(state.get(OBJECT_POS))
        if yaw.shape != shape.shape[:-1] or shape.shape[-1] != 8:
            raise ValueError(
                f"object_yaw must be [*B, N] and object_shape [*B, N, 8], got "
                f"{tuple(yaw.shape)} and {tuple(shape.shape)}."
            )
        angle = torch.stack([yaw.cos(), yaw.sin()], dim=-1)
        return torch.cat([angle, shape / self.position_scale], dim=-1)


class ObjectStateRollout:
    """:class:`~kinet_rl.evaluation.forward.ObjectRollout` of IN/IN-full/VisIN: open-loop on
    positions.

    Node features (IN-full's yaw and shape, VisIN's crops) are computed once from the start frame
    and carried over.
    """

    def __init__(self, model: ObjectInteractionModel) -> None:
        self.model = model

    @torch.no_grad()
    def __call__(self, start: TensorDictBase, actions: Tensor) -> Tensor:
        out_device = actions.device
        device = model_device(self.model)
        start, actions = start.to(device), actions.to(device)
        node_feat = self.model.node_features(start)
        pos = start[OBJECT_POS]
        steps = []
        for h in range(actions.shape[1]):
            pos = self.model.predict(pos, node_feat, actions[:, h])
            steps.append(pos)
        return torch.stack(steps, dim=1).to(out_device)
