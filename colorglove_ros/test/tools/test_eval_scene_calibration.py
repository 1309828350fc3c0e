"""colorglove_eval_scene_calibration: the starting and the scene calibration compared on
held-out frames of a rendered scene, as a table and JSON."""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from repo_paths import CONFIG_DIR
from scene_samples import WARM_SCENE, start_calibration_file

from colorglove_ros.tools import eval_scene_calibration
from colorglove_ros.tools.eval_scene_calibration import REPORT_SEEDS, TUNING_SEEDS, render_scene


def test_tuning_and_report_seeds_are_apart() -> None:
    assert not set(TUNING_SEEDS) & set(REPORT_SEEDS)
    assert WARM_SCENE in TUNING_SEEDS


def test_eval_prints_and_writes_the_comparison(tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'eval.json'
    assert eval_scene_calibration.main([
        '--seeds', str(WARM_SCENE), '--backgrounds', 'procedural', '--json', str(out),
        '--start', str(start_calibration_file(tmp_path)),
        '--config', str(CONFIG_DIR / 'color_calibration.yaml')]) == 0
    assert 'held-out frames of scenes [8]' in capsys.readouterr().out
    figures = json.loads(out.read_text())
    (row,) = figures['scenes']
    assert (row['background'], row['seed'], row['refitted']) == ('office', WARM_SCENE, 10)
    assert row['empty_glove_scene'] < 0.1 * row['empty_glove_start']
    assert row['glove_acc_scene'] > row['glove_acc_start'] + 0.03
    assert figures['means'][0]['glove_acc_scene'] == row['glove_acc_scene']


def test_scenes_are_rendered_deterministically() -> None:
    a = render_scene(11, width=64, height=48, empty=1, glove=1, held_empty=0, held_glove=0)
    b = render_scene(11, width=64, height=48, empty=1, glove=1, held_empty=0, held_glove=0)
    assert (a.empty[0] == b.empty[0]).all() and (a.glove[0] == b.glove[0]).all()
    assert (a.glove_labels[0] > 0).any()
