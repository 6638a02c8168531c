"""Unit tests of the workspace geometry and the action normalisation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kinet_rl.envs.workspace import Workspace, workspace_for


@pytest.mark.parametrize("task", ["blocks", "ycb"])
def test_to_action_and_to_metres_are_inverse_on_numpy_and_torch(task):
    ws = workspace_for(task)
    xy = np.array([[ws.half_size, -ws.half_size], [0.0, 0.5 * ws.half_size]])
    np.testing.assert_allclose(ws.to_action(xy), [[1.0, -1.0], [0.0, 0.5]])
    np.testing.assert_allclose(ws.to_metres(ws.to_action(xy)), xy)
    action = torch.tensor([[-1.0, 1.0, 0.25, 0.0]])
    metres = ws.to_metres(action)
    assert isinstance(metres, torch.Tensor) and metres.dtype == torch.float32
    torch.testing.assert_close(ws.to_action(metres), action)


def test_push_endpoints_maps_clips_and_validates():
    ws = Workspace(half_size=0.2, table_half_size=0.3)
    start, end = ws.push_endpoints(np.array([-1.0, 0.5, 2.0, -3.0]))
    np.testing.assert_allclose(start, [-0.2, 0.1])
    np.testing.assert_allclose(end, [0.2, -0.2])  # clipped to the workspace
    with pytest.raises(ValueError, match="4 finite numbers"):
        ws.push_endpoints(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="4 finite numbers"):
        ws.push_endpoints(np.zeros(3))


def test_workspace_validation_and_lookup():
    with pytest.raises(ValueError, match="half_size must be positive"):
        Workspace(half_size=0.0)
    with pytest.raises(ValueError, match="lies on the table"):
        Workspace(half_size=0.3, table_half_size=0.2)
    with pytest.raises(ValueError, match="Unknown task 'cups'"):
        workspace_for("cups")
    for task in ("blocks", "ycb"):
        ws = workspace_for(task)
        assert ws.table_half_size > ws.half_size > 0
