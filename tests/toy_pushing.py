"""A tiny synthetic pushing dataset (coloured squares) with the kinet_rl dataset API, for the
baselines' tests (its own tests: ``unit/test_baselines_toy_pushing.py``).

For fast tests of forward models, without MuJoCo stepping or rendering: squares
of fixed colours (one per object index) lie on a grey table seen by the blocks task's top camera;
a push moves every square whose centre lies within ``object_half_size`` of the push line, ahead of
the push start and within reach, along the push until the pusher's end point (no
object-object contact); squares do not turn (yaw 0), and each one's ``object_shape`` is its square
given twice. Pushes mix aimed pushes (through a random object) and uniform ones, like
:class:`~kinet_rl.data.RandomPushPolicy`. ``sample`` and ``sample_sequences`` return the same
entries as :func:`kinet_rl.data.load_dataset` splits.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torch import Tensor

from kinet_rl.data.dataset import sample_steps
from kinet_rl.envs.geometry import SceneGeometry
from kinet_rl.envs.workspace import workspace_for
from kinet_rl.keys import (
    ACTION,
    EPISODE,
    OBJECT_POS,
    OBJECT_SHAPE,
    OBJECT_YAW,
    PIXELS,
    PIXELS_0,
    STEP,
)

COLOURS = torch.tensor(
    [[220, 40, 40], [40, 190, 40], [40, 60, 220], [220, 200, 40], [200, 40, 200]],
    dtype=torch.float32,
)
BACKGROUND = 128.0
TASK = "blocks"


def render_squares(object_px: Tensor, half_px: float, image_size: int) -> Tensor:
    """Anti-aliased squares on a grey background.

    Args:
        object_px: ``[*B, N, 2]`` square centres in pixels (pixel centres at integers).
        half_px: Half side of every square in pixels.
        image_size: Side of the image.

    Returns:
        ``[*B, H, W, 3]`` uint8 images; object ``n`` has ``COLOURS[n]``, later objects on top.
    """
    coords = torch.arange(image_size, dtype=torch.float32)
    image = torch.full((*object_px.shape[:-2], image_size, image_size, 3), BACKGROUND)
    for n in range(object_px.shape[-2]):
        cover_x = (half_px + 0.5 - (coords - object_px[..., n, 0, None]).abs()).clamp(0, 1)
        cover_y = (half_px + 0.5 - (coords - object_px[..., n, 1, None]).abs()).clamp(0, 1)
        cover = (cover_y.unsqueeze(-1) * cover_x.unsqueeze(-2)).unsqueeze(-1)  # [*B, H, W, 1]
        image = image * (1 - cover) + COLOURS[n] * cover
    return image.round().to(torch.uint8)


def push_objects(pos: Tensor, start: Tensor, end: Tensor, half_size: float) -> Tensor:
    """Positions ``[B, N, 2]`` after straight pushes ``start -> end`` ``[B, 2]`` (metres)."""
    length = (end - start).norm(dim=-1, keepdim=True).clamp_min(1e-6)  # [B, 1]
    direction = (end - start) / length
    rel = pos - start.unsqueeze(-2)  # [B, N, 2]
    along = (rel * direction.unsqueeze(-2)).sum(-1)  # [B, N]
    lateral = (rel - along.unsqueeze(-1) * direction.unsqueeze(-2)).norm(dim=-1)
    travel = length + half_size - along  # how far the pusher carries the object
    moved = (lateral < half_size) & (along > -half_size) & (travel > 0)
    return pos + torch.where(moved, travel, 0.0).unsqueeze(-1) * direction.unsqueeze(-2)


class ToyPushData:
    """Episodes of synthetic pushes, generated in memory from a seed.

    Args:
        num_episodes: ``E`` episodes.
        episode_length: ``T`` pushes per episode.
        num_objects: ``N`` squares (at most ``len(COLOURS)``).
        image_size: Side of the images.
        object_half_size: Half side of the squares, metres.
        aimed_push_prob: Probability that a push is aimed through a random object.
        seed: Seed of placements and pushes.
    """

    def __init__(
        self,
        num_episodes: int = 64,
        episode_length: int = 10,
        num_objects: int = 3,
        image_size: int = 32,
        object_half_size: float = 0.04,
        aimed_push_prob: float = 0.8,
        seed: int = 0,
    ) -> None:
        if not 1 <= num_objects <= len(COLOURS):
            raise ValueError(f"num_objects must be in [1, {len(COLOURS)}], got {num_objects}.")
        self.geometry = SceneGeometry.of_scene(TASK, "top", image_size)
        workspace = workspace_for(TASK).half_size
        gen = torch.Generator().manual_seed(seed)
        pos = (torch.rand(num_episodes, num_objects, 2, generator=gen) * 2 - 1) * 0.7 * workspace
        positions, actions = [pos], []
        for _ in range(episode_length):
            start, end = self._draw_push(pos, aimed_push_prob, object_half_size, workspace, gen)
            pos = push_objects(pos, start, end, object_half_size).clamp(-workspace, workspace)
            positions.append(pos)
            actions.append(torch.cat([start, end], dim=-1) / workspace)
        self.object_pos = torch.stack(positions, dim=1)  # [E, T+1, N, 2]
        self.action = torch.stack(actions, dim=1)  # [E, T, 4]
        square = torch.tensor([0.0, 0.0, object_half_size, object_half_size]).repeat(2)
        self.object_shape = square.expand(num_episodes, num_objects, 8)  # [E, N, 8]
        projection = self.geometry.projection  # looks straight down from above the origin
        depth = float(projection.position[2]) - self.geometry.object_height
        px_per_metre = image_size / 2 / (depth * projection.tan_half_fovy)
        self.pixels = render_squares(
            self.geometry.objects_to_pixels(self.object_pos),
            object_half_size * px_per_metre,
            image_size,
        )  # [E, T+1, H, W, 3]

    @staticmethod
    def _draw_push(
        pos: Tensor, aimed_prob: float, half_size: float, workspace: float, gen: torch.Generator
    ) -> tuple[Tensor, Tensor]:
        """Push start and end ``[E, 2]`` metres, clipped to the workspace."""
        num_episodes, num_objects = pos.shape[:2]
        target = pos[
            torch.arange(num_episodes), torch.randint(num_objects, (num_episodes,), generator=gen)
        ]
        angle = torch.rand(num_episodes, generator=gen) * 2 * torch.pi
        direction = torch.stack([angle.cos(), angle.sin()], dim=-1)
        normal = torch.stack([-direction[:, 1], direction[:, 0]], dim=-1)
        approach = (1.5 + torch.rand(num_episodes, 1, generator=gen)) * half_size
        offset = (torch.rand(num_episodes, 1, generator=gen) - 0.5) * half_size
        length = (2.5 + 1.5 * torch.rand(num_episodes, 1, generator=gen)) * half_size
        aimed_start = target - approach * direction + offset * normal
        aimed_end = aimed_start + length * direction
        uniform = (torch.rand(num_episodes, 2, 2, generator=gen) * 2 - 1) * workspace
        aimed = torch.rand(num_episodes, 1, generator=gen) < aimed_prob
        start = torch.where(aimed, aimed_start, uniform[:, 0]).clamp(-workspace, workspace)
        end = torch.where(aimed, aimed_end, uniform[:, 1]).clamp(-workspace, workspace)
        return start, end

    def transitions(self, episode: Tensor, step: Tensor) -> TensorDict:
        """The ``[B]`` transitions ``(episode, step)`` with the entries of a dataset batch."""
        return TensorDict(
            {
                PIXELS: self.pixels[episode, step],
                PIXELS_0: self.pixels[episode, 0],
                ACTION: self.action[episode, step],
                OBJECT_POS: self.object_pos[episode, step],
                OBJECT_YAW: self.object_pos.new_zeros(*episode.shape, self.object_pos.shape[2]),
                OBJECT_SHAPE: self.object_shape[episode],
                EPISODE: episode,
                STEP: step,
                "next": {
                    PIXELS: self.pixels[episode, step + 1],
                    OBJECT_POS: self.object_pos[episode, step + 1],
                },
            },
            batch_size=episode.shape,
        )

    def sample(
        self,
        batch_size: int,
        generator: torch.Generator | None = None,
        steps_per_episode: int = 1,
    ) -> TensorDict:
        """``batch_size`` random transitions (see :meth:`transitions` and :func:`sample_steps`)."""
        episode, step = sample_steps(
            self.action.shape[0], self.action.shape[1], batch_size, steps_per_episode, generator
        )
        return self.transitions(episode, step)

    def sample_sequences(
        self, batch_size: int, length: int, generator: torch.Generator | None = None
    ) -> TensorDict:
        """``batch_size`` random windows of ``length`` pushes: pixels/object_pos/object_yaw
        ``[B, L+1, ...]``, object_shape ``[B, N, 8]``."""
        if not 1 <= length <= self.action.shape[1]:
            raise ValueError(f"length must be in [1, {self.action.shape[1]}], got {length}.")
        episode = torch.randint(self.action.shape[0], (batch_size,), generator=generator)
        first = torch.randint(self.action.shape[1] - length + 1, (batch_size,), generator=generator)
        frames = first[:, None] + torch.arange(length + 1)
        return TensorDict(
            {
                PIXELS: self.pixels[episode[:, None], frames],
                PIXELS_0: self.pixels[episode, 0],
                ACTION: self.action[episode[:, None], frames[:, :-1]],
                OBJECT_POS: self.object_pos[episode[:, None], frames],
                OBJECT_YAW: self.object_pos.new_zeros(*frames.shape, self.object_pos.shape[2]),
                OBJECT_SHAPE: self.object_shape[episode],
                EPISODE: episode,
                STEP: first,
            },
            batch_size=[batch_size],
        )
