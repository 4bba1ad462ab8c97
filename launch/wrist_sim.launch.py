"""Simulated wrist: plant_sim + trajectory_generator + adaptive_controller (+ compensator) + tem_controller.

    ros2 launch sma_wrist wrist_sim.launch.py controller:=inverse_adaptive payload_kg:=0.3

plant_sim publishes /clock; every other node runs on it (use_sim_time). The compensator is
started only for controller:=inverse_adaptive (the other modes publish desired
temperatures themselves). params_file:= replaces config/wrist.yaml (e.g. the paper's gains,
config/paper_table_6_1.yaml, applied on top of the defaults).
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
    defaults = PathJoinSubstitution([FindPackageShare('sma_wrist'), 'config', 'wrist.yaml'])
    extra = LaunchConfiguration('params_file')

    def node(executable: str, sim_time: bool, overrides: dict | None = None, **kw) -> Node:
        return Node(package='sma_wrist', executable=executable, name=executable, output='screen',
                    parameters=[defaults, extra, {'use_sim_time': sim_time, **(overrides or {})}], **kw)

    return LaunchDescription([
        DeclareLaunchArgument('controller', default_value='inverse_adaptive',
                              choices=['inverse_adaptive', 'direct_adaptive', 'pid']),
        DeclareLaunchArgument('payload_kg', default_value='0.3', description='payload at 0.09 m [kg]'),
        DeclareLaunchArgument('params_file', default_value=defaults,
                              description='params file applied after config/wrist.yaml'),
        node('plant_sim', False, {'payload_kg': ParameterValue(payload, value_type=float)}),
        node('trajectory_generator', True),
        node('adaptive_controller', True, {'mode': ParameterValue(controller, value_type=str)}),
        node('hysteresis_compensator', True,
             condition=IfCondition(PythonExpression(["'", controller, "' == 'inverse_adaptive'"]))),
        node('tem_controller', True),
    ])
