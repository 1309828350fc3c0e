"""Locate the package's shared files (config, urdf) and the git-ignored ``data/`` folder in a
source checkout or an installed share.

The repository is a colcon workspace source folder: the package folder ``colorglove_ros/``
(package.xml, config/, launch/, urdf/, this Python package) sits beside ``colorglove_msgs/``,
and the git-ignored ``data/`` (pose databases, colour calibration, photos) at the repository
root, beside both."""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ['PACKAGE_NAME', 'DATA_DIR_VARIABLE', 'share_dir', 'repo_dir', 'data_dir',
           'resolve_path']

PACKAGE_NAME = 'colorglove_ros'
DATA_DIR_VARIABLE = 'COLORGLOVE_DATA_DIR'   # where data/ is, for an installed package
_SOURCE_ROOT = Path(__file__).resolve().parent.parent   # the package folder in a checkout


def _in_source_checkout() -> bool:
    return (_SOURCE_ROOT / 'config').is_dir() and (_SOURCE_ROOT / 'package.xml').is_file()


def share_dir() -> Path:
    """The package's share folder: the installed ament share directory when this package was
    installed (non-editable or by colcon), otherwise the package folder of the source checkout
    it runs from (``<repository>/colorglove_ros``)."""
    if _in_source_checkout():
        return _SOURCE_ROOT
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory(PACKAGE_NAME))


def repo_dir() -> Path | None:
    """The repository this package runs from (the folder holding the package folders
    ``colorglove_ros/`` and ``colorglove_msgs/``), or None when it runs installed."""
    if _in_source_checkout():
        return _SOURCE_ROOT.parent
    return None


def data_dir() -> Path:
    """The git-ignored ``data/`` folder: ``$COLORGLOVE_DATA_DIR`` when set, else ``data/`` at
    the root of the source checkout (beside the package folders), else ``data/`` of the
    installed share folder."""
    if os.environ.get(DATA_DIR_VARIABLE):
        return Path(os.environ[DATA_DIR_VARIABLE]).expanduser().resolve()
    root = repo_dir()
    return (root if root is not None else share_dir()) / 'data'


def resolve_path(path: str | Path) -> Path:
    """Resolve a path from a config or parameter: absolute, relative to the working folder if it
    exists there, else ``data/...`` in :func:`data_dir` and anything else (``config/x.yaml``)
    relative to the package share folder."""
    path = Path(path).expanduser()
    if path.is_absolute() or path.exists():
        return path.resolve()
    if path.parts and path.parts[0] == 'data':
        return data_dir().joinpath(*path.parts[1:])
    return share_dir() / path
