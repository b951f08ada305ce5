"""Launch the fence_sorter node suite on a machine with a normal ROS 2 install.

    ros2 launch fence_sorter sorter.launch.py scene:=impact_flexible rtf:=1.0 \
        stream:=default parcels:=20 bag:=bags/run1 sensors:=camera60

Starts the simulator (publishes /clock), the scanner and the controller (use_sim_time), the
recorder when ``bag`` is not empty, and the sensors node when ``sensors`` names a sensors file
(a path or a name under config/sensors/), each with its config/<node>.yaml from the package
share (the sensors node has none). With sensors the nodes are set up as `fence-sorter run
--sensors` sets them (fence_sorter.runner.job): the simulator's state at the rate the sensors
need, the sensors' noise seed and state gap, the measured topics recorded (the truth in the
bag's metadata only by `fence-sorter run`); a sensors file or rtf that run refuses ends the
launch with its one-line reason. `fence-sorter run` does the same without ros2 launch and
prints a summary at the end.
"""

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

PACKAGE = "fence_sorter"


def _nodes(context) -> list:
    """The nodes, set up from the arguments' values (the sensors change the simulator's
    publication rate and the recorder's topics)."""
    from fence_sorter.recording.topics import MEASURED, TOPICS
    from fence_sorter.runner.job import (
        RunOptions,
        load_sensors_arg,
        sensors_node_parameters,
        sensors_seed,
        sensors_state_rate,
        state_publish_rate,
    )
    from fence_sorter.scene import load_scene

    config = Path(get_package_share_directory(PACKAGE)) / "config"
    arg = {
        name: LaunchConfiguration(name).perform(context)
        for name in ("scene", "rtf", "stream", "parcels", "seed", "bag", "sensors")
    }
    scene, stream, bag, rtf = arg["scene"], arg["stream"], arg["bag"], float(arg["rtf"])
    sim_time = {"use_sim_time": True}
    publish, topics = {}, {}
    gate = ["simulator", "controller"] + (["recorder"] if bag else [])
    nodes = []
    if arg["sensors"]:
        cfg = load_sensors_arg(arg["sensors"])
        state_rate = sensors_state_rate(cfg, load_scene(scene).scenario, rtf, arg["sensors"])
        publish = {"publish_rate": state_publish_rate(state_rate, rtf)}
        topics = {"topics": [*TOPICS, *MEASURED]}
        gate.append("sensors")
        seed = sensors_seed(RunOptions(seed=int(arg["seed"]) if int(arg["seed"]) >= 0 else None))
        nodes.append(
            Node(
                package=PACKAGE,
                executable="sensors",
                name="sensors",
                parameters=[{**sensors_node_parameters(scene, arg["sensors"], seed, state_rate)}],
                output="screen",
            )
        )
    nodes += [
        Node(
            package=PACKAGE,
            executable="simulator",
            name="simulator",
            parameters=[
                str(config / "simulator.yaml"),
                {"scene": scene, "real_time_factor": rtf, **publish},
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
                    "parcels": int(arg["parcels"]),
                    "seed": int(arg["seed"]),
                    "start_gate": ",".join(gate),
                    **sim_time,
                },
            ],
            output="screen",
        ),
    ]
    if bag:
        nodes.append(
            Node(
                package=PACKAGE,
                executable="recorder",
                name="recorder",
                parameters=[
                    str(config / "recorder.yaml"),
                    {"output_dir": bag, **sim_time, **topics},
                ],
                output="screen",
            )
        )
    return nodes


def generate_launch_description() -> LaunchDescription:
    args = [
        DeclareLaunchArgument("scene", default_value="impact_flexible", description="scene"),
        DeclareLaunchArgument("rtf", default_value="1.0", description="real-time factor"),
        DeclareLaunchArgument("stream", default_value="default", description="stream or CSV"),
        DeclareLaunchArgument("parcels", default_value="20", description="parcels to inject"),
        DeclareLaunchArgument("seed", default_value="-1", description="-1: the file's seed"),
        DeclareLaunchArgument("bag", default_value="", description="record into this dir"),
        DeclareLaunchArgument(
            "sensors", default_value="", description="sensors file or name (config/sensors)"
        ),
    ]
    return LaunchDescription([*args, OpaqueFunction(function=_nodes)])
