"""How fast the machine is right now: a fixed workload timed beside a speed measurement.

This machine's speed changes by tens of percent within minutes (a virtual machine whose host is
shared), and every timing figure moves with it. A speed figure is readable only with the speed
of the machine it was taken on, so every tool that prints a time (the benchmarks, the edge
tracker's and the segmentation's evaluations, the render benchmark) times the same two small
workloads, which do not depend on this project's code, before its work and after it (the
benchmark also before every pass): a pure-Python loop (the interpreter, where the nodes' glue
runs) and a sort of four million seeded random floats (compiled code on memory, like the
per-pixel and lookup kernels). This module is also the one place the load average is read. No
rclpy import.
"""
from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

__all__ = ['MachineSpeed', 'measure_machine_speed', 'machine_speed_before', 'machine_speed_after',
           'load_average_1min', 'MACHINE_SPEED_TITLE', 'PYTHON_LOOP_STEPS', 'SORTED_VALUES']

PYTHON_LOOP_STEPS = 1_000_000
"""Steps of the reference pure-Python loop."""

SORTED_VALUES = 1 << 22
"""Random float64 values the reference sort orders."""

MACHINE_SPEED_TITLE = ('machine speed: the same fixed workloads before and after the run '
                       '(core.evaluation.machine_speed; slower there = a slower machine, not '
                       'slower code)')
"""The title of the table of :meth:`MachineSpeed.row` rows every timing tool prints."""


@dataclass(frozen=True)
class MachineSpeed:
    """The reference workloads' median times (ms) over ``repeats`` runs, and the 1-minute load
    average when they ran (NaN where the system does not give it)."""

    python_loop_ms: float
    numpy_sort_ms: float
    repeats: int
    load_1min: float

    def row(self, when: str) -> dict[str, Any]:
        """A table row of these figures, labelled ``when`` (e.g. 'before', 'after')."""
        return {'when': when, **asdict(self)}


def _python_loop() -> int:
    total = 0
    for step in range(PYTHON_LOOP_STEPS):
        total += step & 7
    return total


def measure_machine_speed(repeats: int = 5) -> MachineSpeed:
    """Time the reference workloads ``repeats`` times each (at least once) and return their
    medians."""
    repeats = max(int(repeats), 1)
    values = np.random.default_rng(0).random(SORTED_VALUES)
    loop_ms, sort_ms = [], []
    for _ in range(repeats):
        started = time.perf_counter()
        _python_loop()
        loop_ms.append(1e3 * (time.perf_counter() - started))
        started = time.perf_counter()
        np.sort(values)
        sort_ms.append(1e3 * (time.perf_counter() - started))
    return MachineSpeed(float(np.median(loop_ms)), float(np.median(sort_ms)), repeats,
                        load_average_1min())


def machine_speed_before() -> list[dict[str, Any]]:
    """A timing tool's machine-speed rows, begun: the 'before' row, measured now."""
    return [measure_machine_speed().row('before')]


def machine_speed_after(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``rows`` (from :func:`machine_speed_before`) with the 'after' row, measured now,
    appended, and printed under :data:`MACHINE_SPEED_TITLE`; returns ``rows``."""
    from colorglove_ros.core.report import print_table

    rows.append(measure_machine_speed().row('after'))
    print_table(rows, MACHINE_SPEED_TITLE)
    return rows


def load_average_1min() -> float:
    """The system's 1-minute load average now (NaN where the system does not give it)."""
    try:
        return float(os.getloadavg()[0])
    except OSError:
        return float('nan')
