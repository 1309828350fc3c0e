#!/usr/bin/env bash
# Set up everything on a fresh machine: a venv with pinned ROS 2 Jazzy wheels,
# the colorglove_msgs interface package built with cmake into the venv, and
# this package installed (editable). Safe to run again.
set -euo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv=${COLORGLOVE_VENV:-$repo/.venv}
python_bin=${PYTHON:-python3}

if [ ! -x "$venv/bin/python" ]; then
    echo "==> creating venv $venv"
    "$python_bin" -m venv "$venv"
fi
# shellcheck disable=SC1091
. "$venv/bin/activate"

echo "==> installing pinned dependencies"
python -m pip install --quiet --upgrade pip==25.3
python -m pip install --quiet -r "$repo/requirements.txt"

echo "==> fixing include paths in the ROS message wheels' CMake exports"
python "$repo/scripts/fix_cmake_exports.py" "$venv"

echo "==> building colorglove_msgs into the venv"
build_dir=$repo/build/colorglove_msgs
mkdir -p "$repo/build"
cmake -S "$repo/colorglove_msgs" -B "$build_dir" \
    -DCMAKE_INSTALL_PREFIX="$venv" -DCMAKE_PREFIX_PATH="$venv" \
    -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF > "$build_dir.log" 2>&1 \
    || { cat "$build_dir.log"; exit 1; }
cmake --build "$build_dir" -j2 >> "$build_dir.log" 2>&1 || { tail -50 "$build_dir.log"; exit 1; }
cmake --install "$build_dir" >> "$build_dir.log" 2>&1 || { tail -50 "$build_dir.log"; exit 1; }

echo "==> installing colorglove_ros"
python -m pip install --quiet --no-deps --no-build-isolation -e "$repo"

python -c "import rclpy, colorglove_msgs.msg, colorglove_ros; print('colorglove_ros ready in', '$venv')"
