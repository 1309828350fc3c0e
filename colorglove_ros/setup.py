"""Install the colorglove_ros ament_python package."""
from glob import glob
from pathlib import Path

from setuptools import find_packages, setup

PACKAGE_NAME = 'colorglove_ros'

# Every node shell colorglove_ros/ros/nodes/<name>_node.py becomes the command <name>_node.
NODE_SCRIPTS = {
    Path(path).stem: f'colorglove_ros.ros.nodes.{Path(path).stem}:main'
    for path in sorted(glob('colorglove_ros/ros/nodes/*_node.py'))
}

TOOL_SCRIPTS = {'colorglove_launch': 'colorglove_ros.ros.launcher:main',
                'colorglove_single_process': 'colorglove_ros.ros.single_process:main'}
# Every command-line tool colorglove_ros/tools/<name>.py becomes colorglove_<name>.
TOOL_SCRIPTS.update({
    f'colorglove_{Path(path).stem}': f'colorglove_ros.tools.{Path(path).stem}:main'
    for path in sorted(glob('colorglove_ros/tools/*.py')) if not Path(path).stem.startswith('_')
})

setup(
    name=PACKAGE_NAME,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE_NAME}']),
        (f'share/{PACKAGE_NAME}', ['package.xml']),
        (f'share/{PACKAGE_NAME}/config',
         glob('config/*.yaml') + glob('config/*.xml') + glob('config/*.npz')),
        (f'share/{PACKAGE_NAME}/config/visualization', glob('config/visualization/*')),
        (f'share/{PACKAGE_NAME}/launch', glob('launch/*.launch.py')),
        (f'share/{PACKAGE_NAME}/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='colorglove_ros maintainers',
    maintainer_email='maintainers@colorglove-ros.org',
    description='Colour-glove articulated hand tracking (Wang and Popovic 2009) as ROS 2 nodes.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [f'{name} = {target}'
                            for name, target in {**NODE_SCRIPTS, **TOOL_SCRIPTS}.items()],
    },
)
