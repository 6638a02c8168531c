"""The datasets a model can train on, from what it declares (``capabilities``): the arrays it
reads and whether its episodes may hold different object counts."""

from __future__ import annotations

from kinet_rl.data import PushDataset
from kinet_rl.keys import PIXELS
from kinet_rl.planners.world_model import PlanningInterface


def check_dataset_for(model: PlanningInterface, dataset: PushDataset) -> None:
    """Raises ``DatasetMismatchError`` if ``dataset`` stores no array that ``model`` reads, or
    episodes of different object counts that ``model`` cannot train on.

    A model declares the arrays in ``capabilities.observes`` (IN-full: ``object_pos``,
    ``object_yaw``, ``object_shape``; datasets collected by an older kinet_rl lack
    ``object_shape``).
    """
    name = type(model).__name__
    dataset.check_keys([key for key in model.capabilities.observes if key != PIXELS], name)
    if not model.capabilities.any_object_count:
        dataset.check_fixed_object_count(name)
