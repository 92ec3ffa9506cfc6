"""Moves between passes and views (motion.py): straight moves sampled for the collision check."""

from __future__ import annotations

import numpy as np

from scanplan.planning.views import View


def test_a_straight_move_is_sampled_so_every_place_the_body_passes_is_checked():
    from scanplan.planning.motion import straight_move

    start = np.eye(4)
    start[:3, :3] = View.looking_along(np.array([0.98, 0.0, 0.17])).R[:3, :3].T
    moves = straight_move(start, np.array([0.0, 0.0, 95.0]), step_mm=20.0)
    path = np.vstack([start[:3, 3], moves[:, :3, 3]])
    assert len(moves) == 5 and np.allclose(moves[-1, :3, 3], [0, 0, 95])
    assert np.linalg.norm(np.diff(path, axis=0), axis=1).max() <= 20.0
    assert np.allclose(moves[:, :3, :3], start[:3, :3])  # orientation kept
