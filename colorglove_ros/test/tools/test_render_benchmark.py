"""colorglove_render_benchmark on a few renders: its table, the machine's speed, --json."""
import json

from colorglove_ros.core.evaluation.machine_speed import MACHINE_SPEED_TITLE
from colorglove_ros.tools.render_benchmark import main


def test_the_rates_come_with_the_machine_speed_before_and_after(tmp_path, capsys) -> None:
    out = tmp_path / 'render.json'
    assert main(['--images', '2', '--full-images', '1', '--batch', '2', '--json',
                 str(out)]) == 0
    report = json.loads(out.read_text())
    assert report['rows'] and all(row['per_s'] > 0 for row in report['rows'])
    assert [row['when'] for row in report['machine_speed']] == ['before', 'after']
    assert all(row['python_loop_ms'] > 0 and row['numpy_sort_ms'] > 0
               for row in report['machine_speed'])
    assert MACHINE_SPEED_TITLE in capsys.readouterr().out
