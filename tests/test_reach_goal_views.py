"""benchmarks/reach_goal_views.py: the length of a camera ray inside the box of possible goals (hand-computed)."""

import math

import numpy as np
import pytest

from benchmarks.reach_goal_views import ray_length_in_box

UNIT = (np.zeros(3), np.ones(3))


@pytest.mark.parametrize(
    ("origin", "through", "length"),
    [
        ((-1.0, 0.5, 0.5), (0.0, 0.5, 0.5), 1.0),  # along x through the middle: the box's width
        ((-1.0, -1.0, -1.0), (0.0, 0.0, 0.0), math.sqrt(3)),  # the main diagonal
        ((-1.0, -1.0, 0.5), (0.0, 0.0, 0.5), math.sqrt(2)),  # a face diagonal, parallel to z
        ((-1.0, 0.0, 0.5), (0.0, 0.5, 0.5), math.sqrt(1.25)),  # enters at x=0, leaves at y=1 (x=1)
        ((-1.0, 5.0, 0.5), (0.0, 5.0, 0.5), 0.0),  # parallel to the y slab, outside it
        ((-1.0, 0.0, 0.0), (0.0, 3.0, 0.0), 0.0),  # misses the box
    ],
)
def test_ray_length_in_box(origin, through, length):
    assert ray_length_in_box(np.array(origin), np.array(through), *UNIT) == pytest.approx(length, abs=1e-9)
