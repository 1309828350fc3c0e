"""Shared pytest fixtures: a ROS domain of the test's own, and what is built once per session
(the default hand, a small rendered pose database, the node assets)."""
from __future__ import annotations

import itertools
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from colorglove_ros.core.hand.glove import default_hand
from colorglove_ros.core.lookup.database import PoseDatabase, save_database
from colorglove_ros.core.lookup.database_build import build_database
from colorglove_ros.core.tracking.kinematics import FastKinematics
from colorglove_ros.ros.launcher import FASTDDS_PROFILE_VARIABLE

sys.path.insert(0, str(Path(__file__).resolve().parent))

from repo_paths import PKG_DIR  # noqa: E402
from small_databases import SMALL_BUILD  # noqa: E402

if TYPE_CHECKING:
    import rclpy
    from node_fixtures import NodeAssets

    from colorglove_ros.core.hand.glove import Glove
    from colorglove_ros.core.hand.mesh import HandMesh
    from colorglove_ros.core.hand.model import HandModel


_DOMAINS_USED = itertools.count()


@pytest.fixture
def isolated_ros_domain(monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """A ROS domain of this test's own (the next of this test run's, so a participant an
    earlier test left behind until its lease ends is never matched by this one), on loopback
    only, with the Fast DDS profile the launcher uses (shared-memory segments large enough for
    640x480 images, without which best-effort images are lost between processes); returns the
    environment to pass on."""
    domain = str(100 + (os.getpid() + next(_DOMAINS_USED)) % 100)
    monkeypatch.setenv('ROS_DOMAIN_ID', domain)
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv(FASTDDS_PROFILE_VARIABLE, str(PKG_DIR / 'config' / 'fastdds_profile.xml'))
    return dict(os.environ)


@pytest.fixture
def ros_context(isolated_ros_domain: dict[str, str]) -> Iterator[rclpy.Context]:
    """An rclpy context of this test's own, in its own ROS domain; shut down after the test."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture(scope='session')
def hand() -> tuple[HandModel, HandMesh, Glove]:
    """The default (model, mesh, glove); shared by every test, so never modified."""
    return default_hand()


@pytest.fixture(scope='session')
def hand_kinematics(hand: tuple[HandModel, HandMesh, Glove]
                    ) -> tuple[HandModel, HandMesh, FastKinematics]:
    """The default hand model, its mesh and the fast kinematics of the model."""
    model, mesh, _ = hand
    return model, mesh, FastKinematics(model)


@pytest.fixture(scope='session')
def small_database() -> PoseDatabase:
    """The small rendered database of ``small_databases.SMALL_BUILD``, built once per session
    (shared: tests read it, never change it)."""
    return build_database(SMALL_BUILD)


@pytest.fixture(scope='session')
def small_database_path(small_database: PoseDatabase,
                        tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``small_database`` saved to a folder of this session."""
    return save_database(small_database, tmp_path_factory.mktemp('small_database') / 'db')


@pytest.fixture(scope='session')
def node_assets(small_database_path: Path, tmp_path_factory: pytest.TempPathFactory
                ) -> NodeAssets:
    """The files the nodes need (a colour calibration and its config, the small database),
    made on first use in this session."""
    from node_fixtures import build_node_assets

    return build_node_assets(tmp_path_factory.mktemp('node_assets'), small_database_path)
