"""The IK's assignment solver is scipy's compiled one, loaded without scipy.optimize: the same
answers, and an IK node that never imports scipy.optimize (start-up time)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from colorglove_ros.core.tracking.assignment import LOADED_DIRECTLY, linear_sum_assignment


def test_pinned_scipy_takes_the_direct_path() -> None:
    assert LOADED_DIRECTLY


@pytest.mark.parametrize('shape', [(1, 1), (3, 7), (12, 12), (30, 35), (35, 30)])
def test_same_answers_as_scipy_optimize(shape: tuple[int, int]) -> None:
    from scipy.optimize import linear_sum_assignment as public

    rng = np.random.default_rng(sum(shape))
    for _ in range(20):
        cost = rng.uniform(0, 100, shape)
        cost[rng.uniform(size=shape) < 0.5] = 1e4
        got, want = linear_sum_assignment(cost), public(cost)
        assert all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))


def test_the_ik_node_does_not_import_scipy_optimize() -> None:
    code = 'import sys, colorglove_ros.ros.nodes.ik_node; print("scipy.optimize" in sys.modules)'
    loaded = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            check=True).stdout.strip()
    assert loaded == 'False'
