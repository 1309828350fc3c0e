"""Where the tests find the repository's own files, written once for every test folder."""
from __future__ import annotations

from pathlib import Path

__all__ = ['TEST_DIR', 'PKG_DIR', 'REPO_DIR', 'CONFIG_DIR']

TEST_DIR = Path(__file__).resolve().parent
PKG_DIR = TEST_DIR.parent      # the ament_python package folder (colorglove_ros/)
REPO_DIR = PKG_DIR.parent      # the repository: a colcon workspace's source folder
CONFIG_DIR = PKG_DIR / 'config'
