"""colorglove_demo and colorglove_benchmark with a --database that does not exist: a one-line
error naming the path and how to build it, not a silent build of the full database there."""
from __future__ import annotations

from pathlib import Path

import pytest

from colorglove_ros.tools import benchmark, demo


@pytest.mark.parametrize('tool', [demo, benchmark], ids=['demo', 'benchmark'])
def test_a_missing_database_is_an_error_not_a_build(tool, tmp_path: Path, capsys) -> None:
    missing = tmp_path / 'mistyped_database'
    assert tool.main(['--database', str(missing)]) == 1
    error = capsys.readouterr().err
    assert f'no pose database at {missing}' in error
    assert f'colorglove_build_database --output {missing}' in error
    assert not missing.exists()
