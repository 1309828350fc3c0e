"""The package's Fast DDS profile: Fast DDS loads it without an XML error (an invalid profile is
ignored with only a log line, which would silently bring back the small shared-memory
segments), and a respawned node finds the running ones quickly: participants announce
themselves often (at the default 3 s period a restarted node waited up to one period for the
running nodes' next announcement before it matched them) and a killed node's shared-memory port
is given up after a short health check (default one second)."""
from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest
from repo_paths import CONFIG_DIR

from colorglove_ros.ros.launcher import FASTDDS_PROFILE_VARIABLE

PROFILE = CONFIG_DIR / 'fastdds_profile.xml'
NS = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
MAX_ANNOUNCEMENT_PERIOD_S = 0.5
MAX_PORT_HEALTH_CHECK_MS = 500


def test_announcement_period_is_short() -> None:
    root = ET.parse(PROFILE).getroot()
    lease = root.find('f:participant/f:rtps/f:builtin/f:discovery_config/f:leaseAnnouncement',
                      NS)
    assert lease is not None, 'no leaseAnnouncement: Fast DDS announces every 3 s'
    period = float(lease.findtext('f:sec', '0', NS)) + \
        float(lease.findtext('f:nanosec', '0', NS)) * 1e-9
    assert 0.0 < period <= MAX_ANNOUNCEMENT_PERIOD_S


def test_a_dead_port_is_given_up_quickly() -> None:
    """A respawned node reopening the shared-memory port of the node it replaces waits at most
    the health-check timeout for the dead owner."""
    root = ET.parse(PROFILE).getroot()
    shm = [d for d in root.findall('f:transport_descriptors/f:transport_descriptor', NS)
           if d.findtext('f:type', '', NS) == 'SHM']
    assert len(shm) == 1
    timeout = shm[0].findtext('f:healthy_check_timeout_ms', None, NS)
    assert timeout is not None and 0 < int(timeout) <= MAX_PORT_HEALTH_CHECK_MS


@pytest.mark.dds
def test_fast_dds_loads_the_profile_without_error(isolated_ros_domain: dict) -> None:
    env = {**isolated_ros_domain, FASTDDS_PROFILE_VARIABLE: str(PROFILE)}
    done = subprocess.run(
        [sys.executable, '-c', 'import rclpy; rclpy.init(); n = rclpy.create_node("profile"); '
         'n.destroy_node(); rclpy.shutdown()'],
        env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert 'XMLPARSER' not in done.stdout + done.stderr, done.stdout + done.stderr
