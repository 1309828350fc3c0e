"""Where the tests find the repository's own files, written once for every test folder."""
from __future__ import annotations

from pathlib import Path

__all__ = ['TEST_DIR', 'REPO_DIR', 'CONFIG_DIR']

TEST_DIR = Path(__file__).resolve().parent
REPO_DIR = TEST_DIR.parent
CONFIG_DIR = REPO_DIR / 'config'
