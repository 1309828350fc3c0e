"""Native ROS 2 launch file: the four tracker nodes as separate processes.

``ros2 launch colorglove_ros colorglove.launch.py [params_file:=...]
[use_robot_state_publisher:=true]`` (on pip-only machines use
``colorglove_launch config/pipeline.launch.yaml``).
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory('colorglove_ros')
    params_file = LaunchConfiguration('params_file')
    nodes = [
        # respawned after a crash or kill (start-up errors show in the log and repeat)
        Node(package='colorglove_ros', executable=executable, name=name,
             parameters=[params_file], output='screen', respawn=True, respawn_delay=0.5)
        for executable, name in (('camera_node', 'camera'), ('segmentation_node', 'segmentation'),
                                 ('lookup_node', 'lookup'), ('ik_node', 'ik'))
    ]
    with open(os.path.join(share, 'urdf', 'colorglove_hand.urdf')) as urdf_file:
        robot_description = urdf_file.read()
    state_publisher = Node(
        package='robot_state_publisher', executable='robot_state_publisher',
        parameters=[{'robot_description': robot_description}],
        remappings=[('joint_states', '/hand/joint_states')],
        condition=IfCondition(LaunchConfiguration('use_robot_state_publisher')))
    return LaunchDescription([
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'nodes.yaml'),
                              description='ROS 2 parameter file for the four nodes'),
        DeclareLaunchArgument('use_robot_state_publisher', default_value='true',
                              description='also publish the hand URDF as TF'),
        *nodes, state_publisher,
    ])
