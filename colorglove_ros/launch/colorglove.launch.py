"""Native ROS 2 launch file: the tracker nodes as separate processes, and the URDF of the
calibrated hand on ``robot_description`` (robot_state_publisher, which also publishes the finger
TF; or hand_description_node with ``use_robot_state_publisher:=false``).

    ros2 launch colorglove_ros colorglove.launch.py
    ros2 launch colorglove_ros colorglove.launch.py start_camera:=false \\
        image_topic:=/camera/camera/color/image_raw \\
        camera_info_topic:=/camera/camera/color/camera_info
    ros2 launch colorglove_ros colorglove.launch.py namespace:=right frame_prefix:=right_

Arguments: ``image_topic``, ``camera_info_topic`` (the nodes' camera input, remapped),
``start_camera`` (the package's own camera_node; false with your camera driver),
``namespace``, ``frame_prefix`` (hand name in front of every frame and joint name),
``calibration_file`` (given to every node and to the URDF generator, so the IK and the URDF
use one hand length), ``params_file``, ``use_robot_state_publisher`` and ``fastdds_profile``
(``FASTRTPS_DEFAULT_PROFILES_FILE`` for the nodes; '' leaves the environment as it is).
On pip-only machines use ``colorglove_launch config/pipeline.launch.yaml``.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    GroupAction,
    OpaqueFunction,
    SetEnvironmentVariable,
)
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import EnvironmentVariable, LaunchConfiguration
from launch_ros.actions import Node, PushRosNamespace

from colorglove_ros.core.hand.urdf import calibrated_hand_urdf
from colorglove_ros.paths import PACKAGE_NAME, resolve_path
from colorglove_ros.ros.launcher import (
    CAMERA_IMAGE_TOPIC,
    CAMERA_INFO_TOPIC,
    CAMERA_NODE_EXECUTABLE,
    FASTDDS_PROFILE_VARIABLE,
)
from colorglove_ros.ros.nodes.common import JOINT_STATES_TOPIC

# executable, node name (nodes.yaml's "/**/NAME" sections)
TRACKER_NODES = ((CAMERA_NODE_EXECUTABLE, 'camera'), ('segmentation_node', 'segmentation'),
                 ('lookup_node', 'lookup'), ('ik_node', 'ik'))


def _fastdds_profile(context):
    """Point Fast DDS at the ``fastdds_profile`` argument, unless it is empty."""
    profile = LaunchConfiguration('fastdds_profile').perform(context)
    return [SetEnvironmentVariable(FASTDDS_PROFILE_VARIABLE, profile)] if profile else []


def _robot_state_publisher(context):
    """robot_state_publisher with the URDF of the calibrated hand (``calibration_file``'s
    hand length, names with ``frame_prefix``, so its rsp ``frame_prefix`` stays '')."""
    urdf = calibrated_hand_urdf(
        resolve_path(LaunchConfiguration('calibration_file').perform(context)),
        LaunchConfiguration('frame_prefix').perform(context))
    return [Node(package='robot_state_publisher', executable='robot_state_publisher',
                 name='robot_state_publisher', output='screen',
                 parameters=[{'robot_description': urdf}],
                 remappings=[('joint_states', JOINT_STATES_TOPIC)])]


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE_NAME)
    use_robot_state_publisher = LaunchConfiguration('use_robot_state_publisher')
    # launch arguments win over params_file: every node and the URDF see one calibration
    parameters = [LaunchConfiguration('params_file'),
                  {'calibration_file': LaunchConfiguration('calibration_file'),
                   'frame_prefix': LaunchConfiguration('frame_prefix')}]
    remappings = [(CAMERA_IMAGE_TOPIC, LaunchConfiguration('image_topic')),
                  (CAMERA_INFO_TOPIC, LaunchConfiguration('camera_info_topic'))]
    trackers = [
        # respawned after a crash or kill (start-up errors show in the log and repeat)
        Node(package=PACKAGE_NAME, executable=executable, name=name, parameters=parameters,
             remappings=remappings, output='screen', respawn=True, respawn_delay=0.5,
             condition=(IfCondition(LaunchConfiguration('start_camera'))
                        if executable == CAMERA_NODE_EXECUTABLE else None))
        for executable, name in TRACKER_NODES
    ]
    hand_description = Node(
        package=PACKAGE_NAME, executable='hand_description_node', name='hand_description',
        parameters=parameters, output='screen', respawn=True, respawn_delay=0.5,
        condition=UnlessCondition(use_robot_state_publisher))
    arguments = [
        DeclareLaunchArgument('image_topic', default_value=CAMERA_IMAGE_TOPIC,
                              description='camera image topic the tracker subscribes to '
                                          '(relative names follow the namespace)'),
        DeclareLaunchArgument('camera_info_topic', default_value=CAMERA_INFO_TOPIC,
                              description='CameraInfo topic of that camera'),
        DeclareLaunchArgument('start_camera', default_value='true',
                              description="start the package's camera_node (false: images "
                                          'come from your own camera driver)'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='ROS namespace of every node (e.g. one per hand)'),
        DeclareLaunchArgument('frame_prefix', default_value='',
                              description='hand name in front of every frame and joint name '
                                          '(e.g. right_ gives right_palm)'),
        DeclareLaunchArgument('calibration_file',
                              default_value=os.path.join(share, 'config', 'calibration.yaml'),
                              description='camera and hand calibration YAML, given to every '
                                          'node and to the URDF (hand_length_m)'),
        DeclareLaunchArgument('params_file',
                              default_value=os.path.join(share, 'config', 'nodes.yaml'),
                              description='ROS 2 parameter file of the nodes'),
        DeclareLaunchArgument('use_robot_state_publisher', default_value='true',
                              description='robot_state_publisher publishes the hand URDF and '
                                          'its TF (false: hand_description_node publishes '
                                          'the URDF only)'),
        DeclareLaunchArgument('fastdds_profile',
                              default_value=EnvironmentVariable(
                                  FASTDDS_PROFILE_VARIABLE,
                                  default_value=os.path.join(share, 'config',
                                                             'fastdds_profile.xml')),
                              description='Fast DDS XML profile of the nodes (default: the one '
                                          'set in the environment, else the shipped one with '
                                          "shared memory for 640x480 images); '' to leave the "
                                          'environment as it is'),
    ]
    return LaunchDescription([
        *arguments,
        OpaqueFunction(function=_fastdds_profile),
        GroupAction([
            PushRosNamespace(LaunchConfiguration('namespace')),
            *trackers,
            hand_description,
            OpaqueFunction(function=_robot_state_publisher,
                           condition=IfCondition(use_robot_state_publisher)),
        ]),
    ])
