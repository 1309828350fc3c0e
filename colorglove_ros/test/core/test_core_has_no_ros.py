"""The algorithm under core/ is plain Python: no module there imports rclpy or ROS messages, so
everything can run and be tested in one process without DDS."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import colorglove_ros.core

CORE_DIR = Path(colorglove_ros.core.__file__).resolve().parent
ROS_PACKAGES = ('rclpy', 'rcl_interfaces', 'colorglove_msgs', 'sensor_msgs', 'std_msgs',
                'geometry_msgs', 'visualization_msgs', 'builtin_interfaces', 'tf2_msgs',
                'diagnostic_msgs', 'colorglove_ros.ros')


def imported_modules(path: Path) -> set[str]:
    """Every module a source file imports, at any depth (function-level imports included)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


CORE_FILES = sorted(CORE_DIR.rglob('*.py'))


def test_core_files_are_found() -> None:
    assert len(CORE_FILES) > 20


@pytest.mark.parametrize('path', CORE_FILES, ids=lambda p: str(p.relative_to(CORE_DIR)))
def test_core_module_imports_no_ros(path: Path) -> None:
    offending = sorted(name for name in imported_modules(path)
                       if name.split('.')[0] in ROS_PACKAGES
                       or name.startswith('colorglove_ros.ros'))
    assert not offending, f'{path} imports {offending}'


def test_the_check_sees_a_ros_import(tmp_path: Path) -> None:
    module = tmp_path / 'bad.py'
    module.write_text('def f():\n    from rclpy.node import Node\n    return Node\n')
    assert 'rclpy.node' in imported_modules(module)


def test_every_error_of_the_package_is_a_colorglove_error() -> None:
    """One error family: tools and nodes catch ColorGloveError for every failure the package
    raises on purpose, so no typed error may stand outside it."""
    import importlib
    import pkgutil

    import colorglove_ros
    from colorglove_ros.core.errors import ColorGloveError

    strays = []
    for info in pkgutil.walk_packages(colorglove_ros.__path__, 'colorglove_ros.'):
        if '.ros' in info.name or '.tools' in info.name:
            continue                      # these import rclpy/message packages
        module = importlib.import_module(info.name)
        for name, value in vars(module).items():
            if (isinstance(value, type) and issubclass(value, Exception)
                    and value.__module__ == info.name and not issubclass(value, ColorGloveError)):
                strays.append(f'{info.name}.{name}')
    assert not strays, strays
