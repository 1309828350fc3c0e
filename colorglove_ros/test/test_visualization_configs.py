"""The shipped RViz config and Foxglove layout parse and show the topics the nodes publish."""
from __future__ import annotations

import json

import yaml
from repo_paths import CONFIG_DIR

CONFIG = CONFIG_DIR / 'visualization'
SHOWN = ('/hand/markers', '/hand/wrist_pose', '/camera/image_raw', '/robot_description')


def test_rviz_config_parses_and_shows_the_hand() -> None:
    rviz = yaml.safe_load((CONFIG / 'colorglove.rviz').read_text())
    displays = rviz['Visualization Manager']['Displays']
    classes = {d['Class'] for d in displays}
    assert {'rviz_default_plugins/TF', 'rviz_default_plugins/RobotModel',
            'rviz_default_plugins/MarkerArray', 'rviz_default_plugins/Image'} <= classes
    text = (CONFIG / 'colorglove.rviz').read_text()
    assert all(topic in text for topic in SHOWN)


def test_foxglove_layout_parses_and_shows_the_hand() -> None:
    layout = json.loads((CONFIG / 'foxglove_layout.json').read_text())
    panels = set(layout['configById'])
    assert {'3D!hand', 'Image!camera'} <= panels
    text = json.dumps(layout)
    assert all(topic in text for topic in SHOWN)
