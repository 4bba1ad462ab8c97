"""Simulated wrist: plant_sim + trajectory_generator + adaptive_controller (+ compensator) + tem_controller.

    ros2 launch sma_wrist wrist_sim.launch.py controller:=inverse_adaptive payload_kg:=0.3

plant_sim publishes /clock; every other node runs on it (use_sim_time). The compensator is
started only for controller:=inverse_adaptive (the other modes publish desired
temperatures themselves). params_file:= is applied after config/wrist.yaml (e.g. the paper's gains,
config/paper_table_6_1.yaml, on top of the defaults).
"""

from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from launch import LaunchDescription
from sma_wrist.launch_support import flag, graph_specs, node_parameters, on_exit_actions, payload_override


def _graph(context) -> list:
    controller = LaunchConfiguration('controller').perform(context)
    payload = LaunchConfiguration('payload_kg').perform(context)
    defaults = PathJoinSubstitution([FindPackageShare('sma_wrist'), 'config', 'wrist.yaml']).perform(context)
    extra = LaunchConfiguration('params_file').perform(context)

    return [
        Node(
            package='sma_wrist',
            executable=exe,
            name=exe,
            output='screen',
            parameters=node_parameters(defaults, extra, exe, values),
            on_exit=on_exit_actions(exe),
        )
        for exe, values in graph_specs(
            'plant_sim', payload_override(payload), controller, flag(LaunchConfiguration('monitor').perform(context))
        )
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                'controller', default_value='inverse_adaptive', choices=['inverse_adaptive', 'direct_adaptive', 'pid']
            ),
            DeclareLaunchArgument(
                'payload_kg',
                default_value='',
                description='payload at 0.09 m [kg] (default: payload_kg of the params files, 0.3)',
            ),
            DeclareLaunchArgument(
                'params_file',
                default_value='',
                description='params file applied after config/wrist.yaml (default: none)',
            ),
            DeclareLaunchArgument(
                'monitor',
                default_value='false',
                choices=['true', 'false'],
                description='also run twin_monitor: the model beside the wrist, verdicts on /diagnostics '
                '(doc/howto/monitor.md)',
            ),
            OpaqueFunction(function=_graph),
        ]
    )
