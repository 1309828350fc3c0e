"""The machine-speed reference the benchmarks print beside their figures."""
from __future__ import annotations

import math

import pytest

from colorglove_ros.core.evaluation import machine_speed
from colorglove_ros.core.evaluation.machine_speed import measure_machine_speed


def test_the_reference_times_its_workloads(monkeypatch: pytest.MonkeyPatch) -> None:
    """Positive times of the two workloads, at least one run each; a shorter loop and a
    smaller sort time shorter (the figures measure the work, not a constant)."""
    full = measure_machine_speed(repeats=3)
    assert full.repeats == 3 and full.python_loop_ms > 0 and full.numpy_sort_ms > 0
    assert math.isnan(full.load_1min) or full.load_1min >= 0
    monkeypatch.setattr(machine_speed, 'PYTHON_LOOP_STEPS', machine_speed.PYTHON_LOOP_STEPS // 100)
    monkeypatch.setattr(machine_speed, 'SORTED_VALUES', machine_speed.SORTED_VALUES // 100)
    small = measure_machine_speed(repeats=0)
    assert small.repeats == 1
    assert small.python_loop_ms < full.python_loop_ms / 5
    assert small.numpy_sort_ms < full.numpy_sort_ms / 5


def test_a_row_is_labelled_with_when_it_was_taken() -> None:
    speed = machine_speed.MachineSpeed(30.0, 25.0, 5, 0.5)
    assert speed.row('before') == {'when': 'before', 'python_loop_ms': 30.0,
                                   'numpy_sort_ms': 25.0, 'repeats': 5, 'load_1min': 0.5}


def test_before_and_after_rows_are_measured_and_printed(monkeypatch: pytest.MonkeyPatch,
                                                        capsys) -> None:
    """A timing tool's record: the 'before' row when begun, the 'after' row measured when
    finished, the two printed under the shared title."""
    speeds = iter([machine_speed.MachineSpeed(30.0, 25.0, 5, 0.5),
                   machine_speed.MachineSpeed(40.0, 26.0, 5, 1.5)])
    monkeypatch.setattr(machine_speed, 'measure_machine_speed', lambda: next(speeds))
    rows = machine_speed.machine_speed_before()
    assert [row['when'] for row in rows] == ['before']
    assert machine_speed.machine_speed_after(rows) is rows
    assert [(row['when'], row['python_loop_ms']) for row in rows] == [('before', 30.0),
                                                                     ('after', 40.0)]
    assert machine_speed.MACHINE_SPEED_TITLE in capsys.readouterr().out
