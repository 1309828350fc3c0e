"""Targets judged on measured figures: one PASS/FAIL row format for every evaluation tool."""
from __future__ import annotations

import operator
from collections.abc import Callable
from typing import Any

from colorglove_ros.core.errors import ColorGloveError

__all__ = ['COMPARISONS', 'target_row']

COMPARISONS: dict[str, Callable[[float, float], bool]] = {
    '<': operator.lt, '<=': operator.le, '>': operator.gt, '>=': operator.ge}


def target_row(target: str, measured: float, threshold: float, comparison: str = '<'
               ) -> dict[str, Any]:
    """One judged target: ``measured`` against ``threshold`` with ``comparison``, the margin
    ``measured - threshold`` and ``PASS``/``FAIL``."""
    if comparison not in COMPARISONS:
        raise ColorGloveError(f'unknown comparison {comparison!r}, expected one of '
                              f'{sorted(COMPARISONS)}')
    measured, threshold = float(measured), float(threshold)
    passed = COMPARISONS[comparison](measured, threshold)
    return {'target': target, 'measured': measured, 'threshold': threshold,
            'margin': measured - threshold, 'result': 'PASS' if passed else 'FAIL'}
