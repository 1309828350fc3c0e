"""Evaluation tools run without --database look for the largest database in the data folder
(``paths.data_dir()``, the repository root's data/ or $COLORGLOVE_DATA_DIR), not in the
package folder."""
from __future__ import annotations

from pathlib import Path

import pytest

from colorglove_ros.paths import DATA_DIR_VARIABLE
from colorglove_ros.tools import eval_ik, eval_scenes, learn_ik_covariances


@pytest.mark.parametrize('tool', [eval_ik, eval_scenes, learn_ik_covariances])
def test_default_database_is_looked_for_in_the_data_folder(tool, tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture
                                                           ) -> None:
    monkeypatch.setenv(DATA_DIR_VARIABLE, str(tmp_path))
    assert tool.main(['--sequences', '1', '--frames', '2']) != 0
    assert f'no pose database under {tmp_path}' in capsys.readouterr().err
