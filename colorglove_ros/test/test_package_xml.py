"""package.xml declares every third-party import of the package with a rosdep key."""
from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET

from repo_paths import PKG_DIR

# import name -> the rosdep key (rosdistro rosdep/python.yaml, or a ROS package) declaring it;
# None: no rosdep key exists, installed by pip (said in a package.xml comment)
ROSDEP_KEYS = {
    'numpy': 'python3-numpy', 'numba': 'python3-numba', 'scipy': 'python3-scipy',
    'cv2': 'python3-opencv',
    'yaml': 'python3-yaml', 'tqdm': 'python3-tqdm', 'trimesh': 'python3-trimesh-pip',
    'rosbags': 'python3-rosbags-pip', 'matplotlib': 'python3-matplotlib',
    'sklearn': 'python3-sklearn', 'moderngl': None,
    # scikit-learn's own dependency (Debian's python3-sklearn depends on it), pinned in
    # requirements.txt
    'threadpoolctl': 'python3-sklearn', 'rclpy': 'rclpy',
    # numba's own dependency (Debian's python3-numba depends on python3-llvmlite), pinned in
    # requirements.txt; lookup_kernel uses its intrinsic builder for the prefetch hint
    'llvmlite': 'python3-numba',
    'rcl_interfaces': 'rcl_interfaces', 'std_msgs': 'std_msgs', 'sensor_msgs': 'sensor_msgs',
    'geometry_msgs': 'geometry_msgs', 'visualization_msgs': 'visualization_msgs',
    'builtin_interfaces': 'builtin_interfaces', 'colorglove_msgs': 'colorglove_msgs',
    'tf2_msgs': 'tf2_msgs', 'diagnostic_msgs': 'diagnostic_msgs',
    'rosgraph_msgs': 'rosgraph_msgs', 'launch': 'launch',
    'launch_ros': 'launch_ros', 'ament_index_python': 'ament_index_python',
}


def third_party_imports() -> set[str]:
    names = set()
    for path in [*(PKG_DIR / 'colorglove_ros').rglob('*.py'), *(PKG_DIR / 'launch').glob('*.py')]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module.split('.')[0])
    return {n for n in names if n not in sys.stdlib_module_names and n != 'colorglove_ros'}


def test_every_import_has_a_declared_rosdep_key() -> None:
    root = ET.parse(PKG_DIR / 'package.xml').getroot()
    declared = {e.text for e in root if e.tag in ('depend', 'exec_depend', 'build_depend')}
    imports = third_party_imports()
    unknown = sorted(imports - set(ROSDEP_KEYS))
    assert not unknown, f'imports with no known rosdep key: {unknown} (add them here and to ' \
        'package.xml)'
    missing = sorted(ROSDEP_KEYS[n] for n in imports if ROSDEP_KEYS[n] and
                     ROSDEP_KEYS[n] not in declared)
    assert not missing, f'package.xml lacks {missing}'
    assert 'python3-moderngl' not in declared, 'python3-moderngl is not a rosdep key'
