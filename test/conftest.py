"""Shared pytest fixtures."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

from colorglove_ros.ros.launcher import FASTDDS_PROFILE_VARIABLE

sys.path.insert(0, str(Path(__file__).resolve().parent))

from repo_paths import REPO_DIR  # noqa: E402


@pytest.fixture
def isolated_ros_domain(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """A ROS domain of this test run's own, on loopback only, with the Fast DDS profile the
    launcher uses (shared-memory segments large enough for 640x480 images, without which
    best-effort images are lost between processes); returns the environment to pass on."""
    domain = str(100 + os.getpid() % 100)
    monkeypatch.setenv('ROS_DOMAIN_ID', domain)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv(FASTDDS_PROFILE_VARIABLE, str(REPO_DIR / 'config' / 'fastdds_profile.xml'))
    return dict(os.environ)
