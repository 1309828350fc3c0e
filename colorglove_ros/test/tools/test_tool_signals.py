"""A tool that started the nodes (soak, restart, benchmark, ...) stops them when it is itself
stopped with SIGTERM: the nodes run in sessions of their own, so nothing else would."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.dds


def _running(pid: int) -> bool:
    """Whether ``pid`` is a live process (not gone, not a zombie)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != 'Z'


def test_sigterm_to_the_soak_stops_its_nodes(node_assets, isolated_ros_domain: dict) -> None:
    tool = subprocess.Popen(
        [sys.executable, '-m', 'colorglove_ros.tools.soak', '--database',
         str(node_assets.database), '--frames', '20', '--minutes', '10'],
        env=isolated_ros_domain, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    pids: list[int] = []
    try:
        deadline = time.monotonic() + 120.0
        while len(pids) < 4 and time.monotonic() < deadline:
            line = tool.stdout.readline()
            if not line:
                break
            found = re.search(r'\[launch\] started \S+ \(pid (\d+)\)', line)
            if found:
                pids.append(int(found.group(1)))
        assert len(pids) == 4, pids
        assert all(_running(pid) for pid in pids)
        tool.send_signal(signal.SIGTERM)
        tool.communicate(timeout=60.0)
        assert tool.returncode != 0
        deadline = time.monotonic() + 10.0
        while any(_running(pid) for pid in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [pid for pid in pids if _running(pid)]
    finally:
        for pid in pids:
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        if tool.poll() is None:
            tool.kill()
