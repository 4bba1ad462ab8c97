"""Real wrist: hardware_bridge + trajectory_generator + adaptive_controller (+ compensator) + tem_controller.

    ros2 launch sma_wrist wrist_hw.launch.py port:=/dev/ttyACM0 controller:=direct_adaptive payload_kg:=0.3

The same graph as wrist_sim.launch.py with hardware_bridge in place of plant_sim: the
bridge talks to the wrist controller on port:= (doc/explanation/protocol.md; an emulator:
`sma-wrist emulate-device --port /tmp/wrist`) and publishes /clock from device time; every
other node runs on it (use_sim_time). payload_kg:= is the payload actually mounted (it is
published latched and used by the bridge's stress estimate).
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
    port = LaunchConfiguration('port').perform(context)

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
            'hardware_bridge',
            {**payload_override(payload), 'port': port},
            controller,
            flag(LaunchConfiguration('monitor').perform(context)),
        )
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument('port', default_value='/dev/ttyACM0', description='serial port of the wrist'),
            # direct_adaptive by default on hardware: the inverse mode relies on the SD-GPI matching the
            # wires and on the bridge's stress *estimate*; check that with `sma-wrist diagnose` first
            DeclareLaunchArgument(
                'controller', default_value='direct_adaptive', choices=['inverse_adaptive', 'direct_adaptive', 'pid']
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
