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

# Build an interface package from source into the venv (cmake + rosidl from the wheels).
build_interfaces() {
    local name=$1 source=$2
    echo "==> building $name into the venv"
    local build_dir=$repo/build/$name
    mkdir -p "$repo/build" && touch "$repo/build/COLCON_IGNORE"
    cmake -S "$source" -B "$build_dir" \
        -DCMAKE_INSTALL_PREFIX="$venv" -DCMAKE_PREFIX_PATH="$venv" \
        -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF > "$build_dir.log" 2>&1 \
        || { cat "$build_dir.log"; exit 1; }
    cmake --build "$build_dir" -j2 >> "$build_dir.log" 2>&1 || { tail -50 "$build_dir.log"; exit 1; }
    cmake --install "$build_dir" >> "$build_dir.log" 2>&1 || { tail -50 "$build_dir.log"; exit 1; }
}

# tf2_msgs is not among the PyPI wheels: build the standard TFMessage so /tf works everywhere.
if ! python -c "import tf2_msgs.msg" 2>/dev/null; then
    build_interfaces tf2_msgs "$repo/scripts/pip_only/tf2_msgs"
fi
build_interfaces colorglove_msgs "$repo/colorglove_msgs"

echo "==> installing colorglove_ros"
# compat: the package folder goes on sys.path, so from the repository root `colorglove_ros` is
# the Python package colorglove_ros/colorglove_ros/, not the package folder colorglove_ros/
python -m pip install --quiet --no-deps --no-build-isolation \
    --config-settings editable_mode=compat -e "$repo/colorglove_ros"

echo "==> compiling the IK, segmentation, lookup and edge-search kernels (numba, cached on disk beside their modules: once, not per node)"
python -c "from colorglove_ros.core.tracking.ik_kernel import compile_kernels as c; print(f'IK kernels compiled in {c():.1f} s')"
python -c "from colorglove_ros.core.segmentation.segmentation_kernel import compile_kernels as c; print(f'segmentation kernels compiled in {c():.1f} s')"
python -c "from colorglove_ros.core.lookup.lookup_kernel import compile_kernels as c; print(f'lookup kernels compiled in {c():.1f} s')"
python -c "from colorglove_ros.core.tracking.edge_kernel import compile_kernels as c; print(f'edge-search kernels compiled in {c():.1f} s')"

echo "==> installing the photos of synthetic backgrounds (Debian package, see colorglove_ros/config/photos.yaml)"
PYTHON="$venv/bin/python" bash "$repo/scripts/fetch_photos.sh"

python -c "import rclpy, colorglove_msgs.msg, tf2_msgs.msg, colorglove_ros; print('colorglove_ros ready in', '$venv')"
