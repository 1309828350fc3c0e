"""Rewrite the build-machine include paths baked into ROS message wheels' CMake exports.

The ros-jazzy message wheels on PyPI export include folders of the machine they
were built on; CMake refuses them. This points them at this venv's Python and
NumPy include folders. Idempotent.
"""
from __future__ import annotations

import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_MACHINE_PYTHON_INCLUDE = '/opt/python/cp311-cp311/include/python3.11'
BUILD_MACHINE_NUMPY_INCLUDE = (
    '/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include')


def fix_exports(venv: Path) -> int:
    """Rewrite every CMake export under ``venv/share``; return how many files changed."""
    replacements = {
        BUILD_MACHINE_NUMPY_INCLUDE: numpy.get_include(),
        BUILD_MACHINE_PYTHON_INCLUDE: sysconfig.get_paths()['include'],
    }
    changed = 0
    for cmake_file in sorted(venv.glob('share/*/cmake/*.cmake')):
        text = cmake_file.read_text()
        new_text = text
        for old, new in replacements.items():
            new_text = new_text.replace(old, new)
        if new_text != text:
            cmake_file.write_text(new_text)
            changed += 1
    return changed


if __name__ == '__main__':
    print(f'rewrote {fix_exports(Path(sys.argv[1]))} CMake export files')
