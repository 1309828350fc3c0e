"""Tests for the ``TOPIC=VALUE`` argument reader the latency probe and play_bag share."""
from __future__ import annotations

import argparse

import pytest

from colorglove_ros.ros.latency_probe import main as probe_main
from colorglove_ros.topic_arguments import topic_argument


def test_topic_and_value_split_at_the_first_equals_sign() -> None:
    assert topic_argument('TYPE', str)('/hand/obs=colorglove_msgs/msg/HandObservation') == (
        '/hand/obs', 'colorglove_msgs/msg/HandObservation')
    assert topic_argument('COUNT', int)('camera/image_raw=2') == ('camera/image_raw', 2)


@pytest.mark.parametrize('text', ['camera/image_raw', '=2', 'camera/image_raw=', 'a=x'])
def test_a_missing_side_or_a_refused_value_names_the_form(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match='expected TOPIC=COUNT'):
        topic_argument('COUNT', int)(text)


def test_the_probe_refuses_a_stage_topic_without_its_type(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        probe_main(['--output', '/nonexistent/probe.json', '--stage-topics', 'hand/observation'])
    assert exit_info.value.code == 2
    assert 'expected TOPIC=TYPE' in capsys.readouterr().err
