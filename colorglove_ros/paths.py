"""Locate the package's shared files (config, urdf) in a source checkout or an installed share."""
from __future__ import annotations

from pathlib import Path

__all__ = ['PACKAGE_NAME', 'share_dir', 'resolve_path']

PACKAGE_NAME = 'colorglove_ros'
_SOURCE_ROOT = Path(__file__).resolve().parent.parent


def share_dir() -> Path:
    """The package's share folder: the installed ament share directory when this package was
    installed (non-editable or by colcon), otherwise the source checkout it runs from."""
    if (_SOURCE_ROOT / 'config').is_dir() and (_SOURCE_ROOT / 'package.xml').is_file():
        return _SOURCE_ROOT
    from ament_index_python.packages import get_package_share_directory

    return Path(get_package_share_directory(PACKAGE_NAME))


def resolve_path(path: str | Path) -> Path:
    """Resolve a path from a config or parameter: absolute, relative to the working folder if it
    exists there, else relative to the package share folder (``config/x.yaml``, ``data/...``)."""
    path = Path(path).expanduser()
    if path.is_absolute() or path.exists():
        return path.resolve()
    return share_dir() / path
