"""A tool that started the nodes (soak, restart, benchmark, ...) stops them when it is itself
stopped with SIGTERM: the nodes run in sessions of their own, so nothing else would. The
signal is sent as soon as the first node has started, while the tool is still starting the
rest: whatever had started by then must be stopped too, the latency probe included."""
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


def _probe_pids(env: dict) -> list[int]:
    """Latency probes running in this test's ROS domain."""
    found = []
    for entry in Path('/proc').iterdir():
        if not entry.name.isdigit():
            continue
        try:
            command = (entry / 'cmdline').read_bytes()
            environ = (entry / 'environ').read_bytes()
        except OSError:
            continue
        domain = f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}".encode()
        if b'colorglove_ros.ros.latency_probe' in command and domain in environ.split(b'\0'):
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
        pids += [int(pid) for pid in STARTED.findall(rest)]
        assert tool.returncode != 0
        deadline = time.monotonic() + 10.0
        while any(_running(pid) for pid in pids) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [pid for pid in pids if _running(pid)], rest
        assert _probe_pids(isolated_ros_domain) == []
    finally:
        for pid in pids + _probe_pids(isolated_ros_domain):
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        if tool.poll() is None:
            tool.kill()
