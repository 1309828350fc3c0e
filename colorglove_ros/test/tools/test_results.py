"""Tests of colorglove_results: docs/RESULTS.md regenerated from the tools' --json files."""
from __future__ import annotations

import json
from pathlib import Path

from colorglove_ros.tools import results


def test_results_page_holds_every_table_and_scalar(tmp_path: Path) -> None:
    folder = tmp_path / 'json'
    folder.mkdir()
    (folder / 'eval_ik.json').write_text(json.dumps({
        'settings': {'seeds': [0, 1], 'frames': 60},
        'rows': [{'cameras': '1 camera', 'fingertip_mm': 17.67}],
        'targets': [{'target': 'depth < 25 mm', 'measured': 13.07, 'result': 'PASS'}]}))
    (folder / 'eval_ik.cmd').write_text('colorglove_eval_ik --sequences 2 --json eval_ik.json\n')
    out = tmp_path / 'RESULTS.md'
    assert results.main([str(folder), '--output', str(out)]) == 0
    text = out.read_text()
    assert 'Command: `colorglove_eval_ik --sequences 2 --json eval_ik.json`' in text
    assert '| cameras | fingertip_mm |' in text and '| 1 camera | 17.67 |' in text
    assert '| depth < 25 mm | 13.07 | PASS |' in text
    assert '| settings.frames | 60 |' in text


def test_results_refuses_an_empty_folder_and_bad_json(tmp_path: Path, capsys) -> None:
    assert results.main([str(tmp_path), '--output', str(tmp_path / 'R.md')]) == 1
    assert 'no .json files' in capsys.readouterr().err
    (tmp_path / 'broken.json').write_text('{not json')
    assert results.main([str(tmp_path), '--output', str(tmp_path / 'R.md')]) == 1
    assert 'broken.json: not a readable JSON file' in capsys.readouterr().err
