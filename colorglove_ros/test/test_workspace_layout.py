"""The repository is a colcon workspace source folder (issue 15 item 7): colcon never looks
inside a package's folder for another package, so colorglove_ros and colorglove_msgs are
sibling folders, and a plain ``colcon build`` in a workspace whose ``src/`` holds this
repository finds both, and not the pip-only copy of tf2_msgs. The git-ignored ``data/`` stays
at the repository root and the package finds it from any working folder."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from repo_paths import PKG_DIR, REPO_DIR

from colorglove_ros import paths

# colcon-core's ignore marker, and colcon-ros's for catkin / ament_tools workspaces
IGNORE_MARKERS = ('COLCON_IGNORE', 'AMENT_IGNORE', 'CATKIN_IGNORE')
EXPECTED = {'colorglove_ros': PKG_DIR, 'colorglove_msgs': REPO_DIR / 'colorglove_msgs'}


def _package_name(folder: Path) -> str:
    return ET.parse(folder / 'package.xml').getroot().findtext('name', '').strip()


def colcon_discovery(base: Path) -> dict[str, Path]:
    """Packages colcon's default discovery (colcon-recursive-crawl + colcon-ros) finds under
    ``base``: walk the folders (symlinks followed, each real folder once), skip a folder holding
    an ignore marker and any folder whose name starts with a dot, and stop at a package
    folder (one with a package.xml): nothing under a package is looked at."""
    found: dict[str, Path] = {}
    seen: set[str] = set()
    for folder, subfolders, files in os.walk(base, followlinks=True):
        real = os.path.realpath(folder)
        if real in seen or any(marker in files for marker in IGNORE_MARKERS):
            subfolders[:] = []
            continue
        seen.add(real)
        if 'package.xml' in files:
            name = _package_name(Path(folder))
            assert name not in found, f'two packages named {name}: {found[name]}, {folder}'
            found[name] = Path(folder)
            subfolders[:] = []
            continue
        subfolders[:] = sorted(d for d in subfolders if not d.startswith('.'))
    return found


def _tracked_package_folders() -> set[Path]:
    """Folders of the repository's own files holding a package.xml (git's list when this is a
    git checkout, else every package.xml outside hidden folders and build/)."""
    try:
        listed = subprocess.run(['git', 'ls-files', '--', '*package.xml'], cwd=REPO_DIR,
                                capture_output=True, text=True, check=True).stdout.split()
        return {(REPO_DIR / name).parent for name in listed}
    except (OSError, subprocess.CalledProcessError):
        return {p.parent for p in REPO_DIR.rglob('package.xml')
                if not any(part.startswith('.') or part == 'build'
                           for part in p.relative_to(REPO_DIR).parts)}


def _ignored(folder: Path) -> bool:
    """An ignore marker in the folder or one of its parents inside the repository."""
    chain = [folder, *(p for p in folder.parents if REPO_DIR in p.parents or p == REPO_DIR)]
    return any((p / marker).is_file() for p in chain for marker in IGNORE_MARKERS)


def test_colcon_finds_both_packages_from_the_repository_root() -> None:
    assert colcon_discovery(REPO_DIR) == EXPECTED


def test_colcon_finds_both_packages_from_a_workspace(tmp_path: Path) -> None:
    """``git clone ... ws/src/colorglove_ros && cd ws && colcon build``."""
    (tmp_path / 'src').mkdir()
    (tmp_path / 'src' / 'colorglove_ros').symlink_to(REPO_DIR, target_is_directory=True)
    found = colcon_discovery(tmp_path)
    assert {name: path.resolve() for name, path in found.items()} == EXPECTED


def test_every_package_of_the_repository_is_found() -> None:
    """No package nested in another one's folder (colcon would skip it silently), and the
    pip-only tf2_msgs is the only one ignored (a second tf2_msgs would shadow ROS's own)."""
    tracked = _tracked_package_folders()
    ignored = {folder for folder in tracked if _ignored(folder)}
    assert {folder.name for folder in ignored} == {'tf2_msgs'}
    assert set(colcon_discovery(REPO_DIR).values()) == tracked - ignored


def test_no_stray_colcon_packages() -> None:
    """No folder outside the packages that colcon would take for a plain CMake or Python
    package (a CMakeLists.txt with project(), or a setup.py), e.g. in build/ after
    scripts/setup.sh."""
    packages = set(colcon_discovery(REPO_DIR).values())
    for folder, subfolders, files in os.walk(REPO_DIR, followlinks=True):
        here = Path(folder)
        if here in packages or any(marker in files for marker in IGNORE_MARKERS):
            subfolders[:] = []
            continue
        subfolders[:] = [d for d in subfolders if not d.startswith('.')]
        assert 'setup.py' not in files, here
        if 'CMakeLists.txt' in files:
            text = (here / 'CMakeLists.txt').read_text(errors='replace')
            assert not re.search(r'^\s*project\s*\(', text, re.I | re.M), here


@pytest.mark.skipif(shutil.which('colcon') is None, reason='colcon is not installed')
def test_colcon_itself_agrees(tmp_path: Path) -> None:
    out = subprocess.run(['colcon', '--log-base', str(tmp_path), 'list', '--base-paths',
                          str(REPO_DIR)], capture_output=True, text=True, check=True).stdout
    listed = {line.split('\t')[0]: Path(line.split('\t')[1]).resolve()
              for line in out.splitlines() if line.strip()}
    assert listed == EXPECTED


def test_package_files_and_data_are_found_from_any_working_folder(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(paths.DATA_DIR_VARIABLE, raising=False)
    monkeypatch.chdir(tmp_path)
    assert paths.share_dir() == PKG_DIR
    assert paths.repo_dir() == REPO_DIR
    assert paths.data_dir() == REPO_DIR / 'data'
    assert paths.resolve_path('config/nodes.yaml') == PKG_DIR / 'config' / 'nodes.yaml'
    assert paths.resolve_path('data/database_100k') == REPO_DIR / 'data' / 'database_100k'
    assert paths.resolve_path('data') == REPO_DIR / 'data'
    (tmp_path / 'data').mkdir()                 # a data/ in the working folder wins
    assert paths.resolve_path('data/x') == REPO_DIR / 'data' / 'x'
    (tmp_path / 'data' / 'x').touch()
    assert paths.resolve_path('data/x') == tmp_path / 'data' / 'x'
    monkeypatch.setenv(paths.DATA_DIR_VARIABLE, str(tmp_path / 'elsewhere'))
    assert paths.resolve_path('data/db') == tmp_path / 'elsewhere' / 'db'


def test_the_package_imports_from_the_repository_root() -> None:
    """From the repository root, the package folder ``colorglove_ros/`` (no __init__.py) must
    not hide the Python package of the same name: under pytest the root conftest.py imports
    the package first (pytest.ini puts the package folder first on sys.path), and
    ``python -c`` / ``python -m`` from the root still reach the installed package's modules."""
    import colorglove_ros

    assert Path(colorglove_ros.__file__) == PKG_DIR / 'colorglove_ros' / '__init__.py'
    code = 'import colorglove_ros.paths as p; print(p.__file__)'
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO_DIR, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert Path(out) == PKG_DIR / 'colorglove_ros' / 'paths.py'


def test_the_python_package_is_imported_from_the_repository_root() -> None:
    """From the repository root, ``import colorglove_ros`` is the Python package, not the
    package folder of the same name (which has no __init__.py)."""
    found = subprocess.run([sys.executable, '-c', 'import colorglove_ros; '
                            'print(colorglove_ros.__file__)'], cwd=REPO_DIR, text=True,
                           capture_output=True, check=True).stdout.strip()
    assert Path(found) == PKG_DIR / 'colorglove_ros' / '__init__.py'
