"""Starts the mcgnode node as an installed ROS 2 package.

    ros2 launch mcgnode mcgnode.launch.py
    ros2 launch mcgnode mcgnode.launch.py namespace:=/robot1 model:=/path/model.json
    ros2 launch mcgnode mcgnode.launch.py params_file:=/path/params.yaml

Launch arguments:
  model        model file to serve, or truth:spring / truth:pendulum; empty
               (the default) keeps the parameter file's `model`, and with the
               default parameter file serves the installed 5-spring MCGNODE
  namespace    the node's namespace (default: none, i.e. /)
  name         the node's name (default: mcgnode)
  params_file  a parameter file (default: the installed config/spring5.yaml)

The installed parameter files (share/mcgnode/config) and models
(share/mcgnode/models) are the repository's launch_params/ and bags/models/.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def _node(context):
    share = get_package_share_directory('mcgnode')
    default_params = os.path.join(share, 'config', 'spring5.yaml')
    params_file = LaunchConfiguration('params_file').perform(context) or default_params
    model = LaunchConfiguration('model').perform(context)
    if not model and params_file == default_params:
        # The shipped file names its model relative to the repository root.
        model = os.path.join(share, 'models', 'spring5-mcgnode.json')
    parameters = [params_file]
    if model:
        parameters.append({'model': model})
    return [
        Node(
            package='mcgnode',
            executable='mcgnode',
            name=LaunchConfiguration('name'),
            namespace=LaunchConfiguration('namespace'),
            parameters=parameters,
            output='screen',
        )
    ]


def generate_launch_description():
    return LaunchDescription([
        DeclareLaunchArgument(
            'model', default_value='',
            description='model file to serve, or truth:spring / truth:pendulum '
                        "(empty: the parameter file's model)"),
        DeclareLaunchArgument(
            'namespace', default_value='', description="the node's namespace"),
        DeclareLaunchArgument(
            'name', default_value='mcgnode', description="the node's name"),
        DeclareLaunchArgument(
            'params_file', default_value='',
            description='parameter file (empty: the installed config/spring5.yaml)'),
        OpaqueFunction(function=_node),
    ])
