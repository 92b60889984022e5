"""ROS 2 launch description: the simulated arm (``amsfe sim-node``) and the node
(``amsfe node``, the C node when it builds) of one scenario, as ``amsfe live`` starts them
(docs/live-control.md).

    ros2 launch launch/amsfe_live.launch.py scenario:=paper-sim controller:=amsfe lockstep:=true

Arguments: ``scenario`` (paper-sim), ``controller`` (amsfe), ``lockstep`` (true / false),
``duration`` ([s]; empty: the scenario's), ``impl`` (auto / c / python), ``amsfe`` (the
command: ``amsfe`` on the PATH of the venv it is installed in).  Needs a ROS 2 installation
with the ``launch`` package; the ROS 2 wheels this project installs have none (tested here:
the commands it runs are ``amsfe live``'s, tests/test_cnode.py).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction


def _processes(context, *args, **kwargs):  # noqa: ANN001, ANN002, ANN003, ANN202
    def arg(name: str) -> str:
        return context.launch_configurations[name]

    duration = ["--duration", arg("duration")] if arg("duration") else []
    node = [arg("amsfe"), "node", arg("scenario"), "--controller", arg("controller"),
            "--impl", arg("impl"), *duration]  # fmt: skip
    arm = [arg("amsfe"), "sim-node", arg("scenario"), *duration]
    if arg("lockstep").lower() in ("true", "1", "yes"):
        arm.append("--lockstep")
    return [
        ExecuteProcess(cmd=node, name="amsfe_node", output="screen"),
        ExecuteProcess(cmd=arm, name="amsfe_sim", output="screen"),
    ]


def generate_launch_description() -> LaunchDescription:
    """The two processes and their arguments."""
    defaults = {
        "scenario": "paper-sim",
        "controller": "amsfe",
        "lockstep": "true",
        "duration": "",
        "impl": "auto",
        "amsfe": "amsfe",
    }
    return LaunchDescription(
        [
            *(DeclareLaunchArgument(k, default_value=v) for k, v in defaults.items()),
            OpaqueFunction(function=_processes),
        ]
    )
