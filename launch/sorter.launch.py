"""Launch the fence_sorter node suite on a machine with a normal ROS 2 install.

    ros2 launch fence_sorter sorter.launch.py scene:=impact_flexible rtf:=1.0 \
        stream:=default parcels:=20 bag:=bags/run1

Starts the simulator (publishes /clock), the scanner and the controller (use_sim_time), and
the recorder when ``bag`` is not empty, each with its config/<node>.yaml from the package share.
`fence-sorter run` does the same without ros2 launch and prints a summary at the end.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node

from launch import LaunchDescription

PACKAGE = "fence_sorter"


def generate_launch_description() -> LaunchDescription:
    config = Path(get_package_share_directory(PACKAGE)) / "config"
    scene = LaunchConfiguration("scene")
    stream = LaunchConfiguration("stream")
    bag = LaunchConfiguration("bag")
    args = [
        DeclareLaunchArgument("scene", default_value="impact_flexible", description="scene"),
        DeclareLaunchArgument("rtf", default_value="1.0", description="real-time factor"),
        DeclareLaunchArgument("stream", default_value="default", description="stream or CSV"),
        DeclareLaunchArgument("parcels", default_value="20", description="parcels to inject"),
        DeclareLaunchArgument("seed", default_value="-1", description="-1: the file's seed"),
        DeclareLaunchArgument("bag", default_value="", description="record into this dir"),
    ]
    sim_time = {"use_sim_time": True}
    nodes = [
        Node(
            package=PACKAGE,
            executable="simulator",
            name="simulator",
            parameters=[
                str(config / "simulator.yaml"),
                {"scene": scene, "real_time_factor": LaunchConfiguration("rtf")},
            ],
            output="screen",
        ),
        Node(
            package=PACKAGE,
            executable="controller",
            name="controller",
            parameters=[
                str(config / "controller.yaml"),
                {"scene": scene, "warmup_stream": stream, **sim_time},
            ],
            output="screen",
        ),
        Node(
            package=PACKAGE,
            executable="scanner",
            name="scanner",
            parameters=[
                str(config / "scanner.yaml"),
                {
                    "scene": scene,
                    "stream": stream,
                    "parcels": LaunchConfiguration("parcels"),
                    "seed": LaunchConfiguration("seed"),
                    "start_gate": "simulator,controller,recorder",
                    **sim_time,
                },
            ],
            output="screen",
        ),
        Node(
            package=PACKAGE,
            executable="recorder",
            name="recorder",
            parameters=[str(config / "recorder.yaml"), {"output_dir": bag, **sim_time}],
            condition=IfCondition(PythonExpression(["'", bag, "' != ''"])),
            output="screen",
        ),
    ]
    return LaunchDescription(args + nodes)
