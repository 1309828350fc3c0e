"""A tool that started the nodes (soak, restart, benchmark, ...) stops them when it is itself
stopped with SIGTERM: the nodes run in sessions of their own, so nothing else would. The
signal is sent as soon as the first node has started, while the tool is still starting the
rest: whatever had started by then must be stopped too, the latency probe included, and
so must a node whose start the signal interrupted (no process of the test's ROS domain is left)."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.dds, pytest.mark.slow]

STARTED = re.compile(r'\[launch\] started \S+ \(pid (\d+)\)')


def _running(pid: int) -> bool:
    """Whether ``pid`` is a live process (not gone, not a zombie)."""
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != 'Z'


def _domain_pids(env: dict) -> list[int]:
    """Live processes in this test's ROS domain (the tool's nodes and probe inherit it), also
    ones started but never announced."""
    found = []
    domain = f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}".encode()
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / 'environ').read_bytes()
        except OSError:
            continue
        if domain in environ.split(b'\0') and _running(int(entry.name)):
            found.append(int(entry.name))
    return found


def test_sigterm_while_starting_stops_everything_started(node_assets,
                                                         isolated_ros_domain: dict) -> None:
    tool = subprocess.Popen(
        [sys.executable, '-m', 'colorglove_ros.tools.soak', '--database',
         str(node_assets.database), '--frames', '20', '--minutes', '10'],
        env=isolated_ros_domain, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    pids: list[int] = []
    try:
        for line in tool.stdout:
            found = STARTED.search(line)
            if found:
                pids.append(int(found.group(1)))
                tool.send_signal(signal.SIGTERM)
                break
        assert pids, 'the soak started no node'
        rest, _ = tool.communicate(timeout=60.0)
        # the tool waits for what it stops: anything of its domain alive now was never stopped
        left = _domain_pids(isolated_ros_domain)
        pids += [int(pid) for pid in STARTED.findall(rest)]
        assert tool.returncode != 0
        assert left == [], rest
        deadline = time.monotonic() + 10.0
        while any(_running(pid) for pid in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [pid for pid in pids if _running(pid)], rest
    finally:
        for pid in pids + _domain_pids(isolated_ros_domain):
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        if tool.poll() is None:
            tool.kill()
