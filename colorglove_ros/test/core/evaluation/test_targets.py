"""Tests of the one PASS/FAIL row format (core/evaluation/targets.py)."""
from __future__ import annotations

import pytest

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.core.evaluation.targets import target_row


@pytest.mark.parametrize(('measured', 'threshold', 'comparison', 'result'), [
    (14.9, 15.0, '<', 'PASS'), (15.0, 15.0, '<', 'FAIL'), (15.0, 15.0, '<=', 'PASS'),
    (30.0, 30.0, '>=', 'PASS'), (29.9, 30.0, '>=', 'FAIL'), (31.0, 30.0, '>', 'PASS'),
])
def test_target_row_judges_and_reports_the_margin(measured: float, threshold: float,
                                                  comparison: str, result: str) -> None:
    row = target_row('figure', measured, threshold, comparison)
    assert row == {'target': 'figure', 'measured': measured, 'threshold': threshold,
                   'margin': pytest.approx(measured - threshold), 'result': result}


def test_target_row_refuses_an_unknown_comparison() -> None:
    with pytest.raises(ColorGloveError, match='unknown comparison'):
        target_row('figure', 1.0, 2.0, '=<')
