"""The C node and the C arm built with CMake and ament_cmake (``ros/c/CMakeLists.txt``, the
build of a user with a ROS 2 installation; docs/live-control.md, "With a ROS 2 installation
(CMake)"), here against the ROS 2 wheels of this environment (the ``[ament]`` extra): the
sources the wheel build compiles, the libraries it links, and over real DDS in lockstep
(marker ``ros``) the CMake-built node's record equals ``amsfe simulate`` bit for bit.
Skipped, with the reason, without cmake or ament_cmake.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from importlib.util import find_spec
from pathlib import Path

import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario
from tests.test_cnode import _lockstep, assert_is_simulate
from tests.test_ros import SRC

PROGRAMS = ("amsfe_node", "amsfe_arm")


def _cmake() -> str:
    """The cmake command, or skip: no cmake, no ament_cmake, no ROS 2 wheels."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    cmake = shutil.which("cmake")
    if cmake is None:
        pytest.skip("cmake not on PATH (apt-get install cmake)")
    config = Path(sys.prefix) / "share" / "ament_cmake" / "cmake" / "ament_cmakeConfig.cmake"
    if not config.is_file() or not all(map(find_spec, ("ament_package", "catkin_pkg"))):
        pytest.skip("ament_cmake not installed (pip install -e '.[ament]')")
    return cmake


@pytest.fixture(scope="module")
def cmake_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``cmake -S ros/c -B BUILD -DCMAKE_PREFIX_PATH=<venv>`` for paper-sim's library against
    this environment's ROS 2 wheels (docs/live-control.md's commands; no AMENT_PREFIX_PATH,
    no Python3_EXECUTABLE: the venv's), then ``cmake --build BUILD``: the folder."""
    from amsfe_sym.ros.cnode_build import C_DIR

    cmake = _cmake()
    lib = library_for(load_scenario("paper-sim"))
    build = tmp_path_factory.mktemp("cmake") / "build"
    # no ROS installation sourced: the CMakeLists takes ament's index and Python from the venv
    env = {k: v for k, v in os.environ.items() if k != "AMENT_PREFIX_PATH"}
    configure = [
        cmake, "-S", str(C_DIR), "-B", str(build), f"-DCMAKE_PREFIX_PATH={sys.prefix}",
        f"-DAMSFE_GENERATED_DIR={lib.library_path.parent}", "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON",
    ]  # fmt: skip
    for cmd in (configure, [cmake, "--build", str(build)]):
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0, f"{cmd}:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    return build


def _dynamic(exe: Path) -> tuple[set[str], list[str], list[str]]:
    """``readelf -d exe``: its NEEDED libraries, its RPATH and its RUNPATH entries."""
    out = subprocess.run(["readelf", "-dW", str(exe)], capture_output=True, text=True, check=True)
    needed, rpath, runpath = set(), [], []
    for line in out.stdout.splitlines():
        value = line.partition("[")[2].rstrip("]")
        if "(NEEDED)" in line:
            needed.add(value)
        elif "(RPATH)" in line:
            rpath = value.split(":")
        elif "(RUNPATH)" in line:
            runpath = value.split(":")
    return needed, rpath, runpath


@pytest.mark.slow
def test_cmake_builds_what_the_wheel_build_builds(cmake_build: Path) -> None:
    """CMake compiles, for the node and for the arm, exactly the C files the wheel build
    compiles (``cnode_build.PROGRAMS``: a C file added to ``ros/c/``, or given to the arm
    there, fails here until CMakeLists.txt agrees), with the wheel build's flags, and links
    the libraries the wheel-built programs link (no libpython, no system OpenSSL beside the
    wheels' bundled one), through an old-style RPATH to the wheels' ``lib/`` and
    ``ros_*.libs`` without an empty entry."""
    from amsfe_sym.ros.cnode_build import CNODE_CFLAGS, _sources, build_node, ros_paths

    lib = library_for(load_scenario("paper-sim"))
    compiled: dict[str, set[str]] = {p: set() for p in PROGRAMS}
    for unit in json.loads((cmake_build / "compile_commands.json").read_text()):
        words = unit["command"].split()  # ... -O1 -std=gnu11 -o CMakeFiles/P.dir/F.o -c F
        program = Path(words[words.index("-o") + 1]).parts[1].removesuffix(".dir")
        compiled[program].add(Path(unit["file"]).name)
        assert words[-6:-4] == list(CNODE_CFLAGS) and words.count("-O1") == 1, words
    ros = ros_paths()
    for program in PROGRAMS:
        want = {p.name for p in _sources(program) if p.suffix == ".c"}
        assert compiled[program] == want, program
        needed, rpath, runpath = _dynamic(cmake_build / program)
        wheel_needed = _dynamic(build_node(lib, program=program).path)[0]
        assert needed == wheel_needed, program
        assert not runpath and "" not in rpath, rpath
        assert {str(ros.lib), *map(str, ros.bundled)} <= set(rpath), rpath


@pytest.mark.ros
@pytest.mark.slow
def test_cmake_node_lockstep_is_simulate(cmake_build: Path, tmp_path: Path) -> None:
    """The CMake-built node (``amsfe node --node-exe BUILD/amsfe_node``) over DDS in lockstep
    with ``amsfe sim-node``: its record is ``amsfe simulate``'s compiled loop bit for bit
    (estimates, std, theta, commands, truth every tick; frames fused and refused), as the
    wheel-built node's is (tests/test_cnode.py)."""
    sc = load_scenario("paper-sim").with_overrides(duration=1.0)
    node = ("--node-exe", str(cmake_build / "amsfe_node"))
    got = _lockstep(tmp_path, "paper-sim", "c", 1.0, node_args=node)
    assert_is_simulate(got, sc, library_for(sc))


@pytest.mark.ros
@pytest.mark.slow
def test_cmake_node_and_arm_lockstep_is_simulate(cmake_build: Path, tmp_path: Path) -> None:
    """Both CMake-built programs over DDS in lockstep (``amsfe sim-node --arm-exe
    BUILD/amsfe_arm`` + ``amsfe node --node-exe BUILD/amsfe_node``): the node's record is
    ``amsfe simulate``'s compiled loop bit for bit, as with the wheel-built arm."""
    sc = load_scenario("paper-sim").with_overrides(duration=1.0)
    node = ("--node-exe", str(cmake_build / "amsfe_node"))
    arm = ("--arm-exe", str(cmake_build / "amsfe_arm"))
    got = _lockstep(tmp_path, "paper-sim", "c", 1.0, node_args=node, arm_args=arm)
    assert_is_simulate(got, sc, library_for(sc))


@pytest.mark.parametrize("command", ["node", "sim-node"])
def test_a_missing_exe_is_one_line(command: str, tmp_path: Path) -> None:
    """``--node-exe`` / ``--arm-exe`` naming no executable: one error line naming the
    option, the file and the fix, exit 2, before anything starts."""
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    option = "--node-exe" if command == "node" else "--arm-exe"
    missing = tmp_path / "build" / "amsfe_x"
    args = [command, "paper-sim", option, str(missing), "--duration", "0.01"]
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    proc = subprocess.run(
        [sys.executable, "-m", "amsfe_sym", *args],
        env=env, capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stdout + proc.stderr
    lines = [x for x in proc.stderr.splitlines() if x.startswith("error:")]
    assert len(lines) == 1 and option in lines[0] and str(missing) in lines[0], proc.stderr
    assert "Fix: give the amsfe_" in lines[0] and "cmake --build" in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == [], proc.stderr
