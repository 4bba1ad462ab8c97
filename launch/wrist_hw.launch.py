"""Real wrist: hardware_bridge + trajectory_generator + adaptive_controller (+ compensator) + tem_controller.

    ros2 launch sma_wrist wrist_hw.launch.py port:=/dev/ttyACM0 controller:=direct_adaptive payload_kg:=0.3

The same graph as wrist_sim.launch.py with hardware_bridge in place of plant_sim: the
bridge talks to the wrist controller on port:= (docs/protocol.md; an emulator:
`sma-wrist emulate-device --port /tmp/wrist`) and publishes /clock from device time; every
other node runs on it (use_sim_time). payload_kg:= is the payload actually mounted (it is
published latched and used by the bridge's stress estimate).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description() -> LaunchDescription:
    controller = LaunchConfiguration('controller')
    payload = LaunchConfiguration('payload_kg')
    port = LaunchConfiguration('port')
    defaults = PathJoinSubstitution([FindPackageShare('sma_wrist'), 'config', 'wrist.yaml'])
    extra = LaunchConfiguration('params_file')

    def node(executable: str, sim_time: bool, overrides: dict | None = None, **kw) -> Node:
        return Node(package='sma_wrist', executable=executable, name=executable, output='screen',
                    parameters=[defaults, extra, {'use_sim_time': sim_time, **(overrides or {})}], **kw)

    return LaunchDescription([
        DeclareLaunchArgument('port', default_value='/dev/ttyACM0', description='serial port of the wrist'),
        # direct_adaptive by default on hardware: the inverse mode relies on the SD-GPI matching the
        # wires and on the bridge's stress *estimate*; check that with `sma-wrist diagnose` first
        DeclareLaunchArgument('controller', default_value='direct_adaptive',
                              choices=['inverse_adaptive', 'direct_adaptive', 'pid']),
        DeclareLaunchArgument('payload_kg', default_value='0.3', description='payload at 0.09 m [kg]'),
        DeclareLaunchArgument('params_file', default_value=defaults,
                              description='params file applied after config/wrist.yaml'),
        node('hardware_bridge', False, {'payload_kg': ParameterValue(payload, value_type=float),
                                        'port': ParameterValue(port, value_type=str)}),
        node('trajectory_generator', True),
        node('adaptive_controller', True, {'mode': ParameterValue(controller, value_type=str)}),
        node('hysteresis_compensator', True,
             condition=IfCondition(PythonExpression(["'", controller, "' == 'inverse_adaptive'"]))),
        node('tem_controller', True),
    ])
