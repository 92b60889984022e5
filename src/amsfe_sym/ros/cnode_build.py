"""The C node's build (``amsfe node --impl c``; docs/live-control.md, "The build"):
``ros/c/*.c`` compiled against the ROS 2 wheels' rcl (headers under
``<prefix>/include/<pkg>/<pkg>/``, libraries in ``<prefix>/lib/`` and the wheels' bundled ones
in ``site-packages/ros_<pkg>.libs/``, reached through an old-style RPATH:
``-Wl,--disable-new-dtags``, since RUNPATH does not reach librcl's own dependencies) and the
robot's generated library, cached by content in ``$AMSFE_GENERATED_DIR/amsfe_node/<hash>/``
like the libraries (the same sources, library, compiler, flags and rcl compile once), with
its own copy of the library (a library regenerated in place never changes a built node).

librcl's wheel links the Python type support of every message package; of its Python symbols
two are data resolved at load (``PyExc_RuntimeError``, ``_Py_TrueStruct``), which
``amsfe_pystub.c`` defines; the functions are never called and are bound lazily: no
libpython, no interpreter in the node.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import sysconfig
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

from amsfe_sym.codegen.cache import build_lock, compiler, default_out_dir
from amsfe_sym.core.interrupts import checkpoint
from amsfe_sym.errors import ConfigError, RosError, describe
from amsfe_sym.runtime.library import ModelLibrary, file_sha256

__all__ = [
    "CNODE_CFLAGS",
    "C_DIR",
    "EXTRA_FLAGS_ENV",
    "CNodeBuild",
    "RosPaths",
    "build_inputs",
    "build_node",
    "external_build",
    "ros_paths",
    "run_program",
]

#: The C sources of the node (this package's ``ros/c/``).
C_DIR = Path(__file__).with_name("c")
#: Flags of the node's build (-O1 as the generated libraries: the node's own code is small).
CNODE_CFLAGS: tuple[str, ...] = ("-O1", "-std=gnu11")
#: Environment variable of extra compiler and linker flags (shell words) appended to
#: :data:`CNODE_CFLAGS`, e.g. ``-g -fsanitize=address,undefined`` for a sanitizer build
#: (tools/cnode_asan.py): hashed into the cache key, so such a build never replaces the
#: normal one (unset or empty: the normal build, its key unchanged).
EXTRA_FLAGS_ENV = "AMSFE_CNODE_EXTRA_FLAGS"
#: The message packages the node's topics use (their C type support is linked).
_MSG_PACKAGES = (
    "sensor_msgs",
    "geometry_msgs",
    "std_msgs",
    "builtin_interfaces",
    "lifecycle_msgs",
)
#: The Python type support's data symbols librcl's wheel needs at load (amsfe_pystub.c).
_PY_DATA_SYMBOLS = ("PyExc_RuntimeError", "_Py_TrueStruct")


@dataclass(frozen=True)
class RosPaths:
    """Where the ROS 2 wheels put rcl's C side.

    Attributes:
        include: ``-I`` folders (``<prefix>/include/<pkg>``, each holding ``<pkg>/``).
        lib: ``<prefix>/lib`` (librcl, the message libraries).
        bundled: ``site-packages/ros_<pkg>.libs`` (the wheels' bundled libraries).
        rcl_version: The ``ros-rcl`` distribution's version (hashed into the cache key).
    """

    include: tuple[Path, ...]
    lib: Path
    bundled: tuple[Path, ...]
    rcl_version: str


def ros_paths(prefix: Path | None = None) -> RosPaths:
    """rcl's headers and libraries in the environment ``prefix`` (default this Python's).

    Raises:
        RosError: the ROS 2 wheels (the ``[ros]`` extra) are not installed there.
    """
    root = Path(prefix or sys.prefix)
    header = root / "include" / "rcl" / "rcl" / "rcl.h"
    lib = root / "lib"
    if not header.is_file() or not (lib / "librcl.so").is_file():
        raise RosError(
            describe(
                "the C node's build",
                f"rcl's C headers and librcl.so from the ROS 2 wheels under {root}",
                f"no {header if not header.is_file() else lib / 'librcl.so'}",
                'pip install -e ".[ros]" (or run the Python node: amsfe node --impl python)',
            )
        )
    include = tuple(sorted(d for d in (root / "include").iterdir() if (d / d.name).is_dir()))
    purelib = Path(sysconfig.get_paths(vars={"base": str(root), "platbase": str(root)})["purelib"])
    bundled = tuple(sorted(purelib.glob("ros_*.libs")))
    try:
        version = metadata.version("ros-rcl")
    except metadata.PackageNotFoundError:
        version = "unknown"
    return RosPaths(include, lib, bundled, version)


@dataclass(frozen=True)
class CNodeBuild:
    """A built C node.

    Attributes:
        path: The executable.
        key: Its content hash.
        compiled: Whether this call compiled it (False: reused from the cache).
    """

    path: Path
    key: str
    compiled: bool


#: The C files every program of ``ros/c/`` links: the shared rcl set-up and the two data
#: symbols of librcl's Python type support.
SHARED: tuple[str, ...] = ("amsfe_rcl.c", "amsfe_pystub.c")
#: The programs built from ``ros/c/``: their own C files and :data:`SHARED` (``amsfe_node``:
#: every other one).  ``amsfe_arm`` is the simulated arm of ``amsfe sim-node --impl c``
#: (:mod:`amsfe_sym.ros.carm`).
PROGRAMS: dict[str, tuple[str, ...]] = {
    "amsfe_arm": (
        "amsfe_arm.c",
        "amsfe_arm_commands.c",
        "amsfe_arm_config.c",
        "amsfe_arm_sensors.c",
        *SHARED,
    )
}
#: Message packages a program needs besides :data:`_MSG_PACKAGES`.
_EXTRA_PACKAGES: dict[str, tuple[str, ...]] = {"amsfe_arm": ("rosgraph_msgs",)}


def _sources(program: str = "amsfe_node") -> list[Path]:
    """The C sources of ``program`` (``ros/c/*.c``) and every header, sorted."""
    own = PROGRAMS.get(program)
    others = {name for files in PROGRAMS.values() for name in files if name not in SHARED}
    c = [p for p in C_DIR.glob("*.c") if (p.name in own if own else p.name not in others)]
    return sorted([*c, *C_DIR.glob("*.h")])


def build_inputs(lib: ModelLibrary, program: str, ros: RosPaths, cc: str) -> dict[str, Any]:
    """What a build of ``program`` for ``lib`` is keyed by (its content hash): the sources,
    the library, the compiler, the flags (:data:`EXTRA_FLAGS_ENV`'s too, when set), rcl's
    version and the environment's prefix."""
    gen = hashlib.sha256()
    for path in _sources(program):
        gen.update(path.name.encode() + b"\0" + path.read_bytes())
    extra_flags = tuple(shlex.split(os.environ.get(EXTRA_FLAGS_ENV, "")))
    return {
        "sources": gen.hexdigest(),
        "library": lib.manifest.raw.get("content_hash"),
        "library_sha256": lib.manifest.raw.get("library_sha256"),
        "library_path": str(lib.library_path),
        "compiler": _compiler_line(cc),
        "cflags": list(CNODE_CFLAGS),
        "rcl": ros.rcl_version,
        "prefix": str(sys.prefix),
        **({"program": program} if program != "amsfe_node" else {}),
        **({"extra_flags": list(extra_flags)} if extra_flags else {}),
    }


def build_node(
    lib: ModelLibrary, out_dir: Path | None = None, program: str = "amsfe_node"
) -> CNodeBuild:
    """The C node (or another ``program`` of :data:`PROGRAMS`: ``amsfe_arm``) of ``lib``'s
    robot, compiled once per content (sources, the library's content hash and file,
    compiler, flags, rcl's version) under ``out_dir`` (default ``$AMSFE_GENERATED_DIR``, else
    the generated libraries' folder) / ``<program>/<hash>/``.

    Raises:
        RosError: the ROS 2 wheels are missing, or the compiler failed (its last lines).
    """
    ros = ros_paths()
    cc = compiler()
    srcs = [p for p in _sources(program) if p.suffix == ".c"]
    inputs = build_inputs(lib, program, ros, cc)
    extra_flags = tuple(inputs.get("extra_flags", ()))
    key = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:20]
    folder = (out_dir or default_out_dir()) / program / key
    exe = folder / program
    if exe.is_file() and os.access(exe, os.X_OK):
        return CNodeBuild(exe, key, False)
    with build_lock(folder.parent / f"{key}.lock"):
        if exe.is_file():
            return CNodeBuild(exe, key, False)
        folder.mkdir(parents=True, exist_ok=True)
        # the node's own copy of the library and its headers: a library regenerated in place
        # later (another scenario's, another checkout's) never changes a built node
        gen_dir = lib.library_path.parent
        for src in [lib.library_path, *sorted(gen_dir.glob("*.h"))]:
            shutil.copy2(src, folder / src.name)
        if file_sha256(folder / lib.library_path.name) != inputs["library_sha256"]:
            raise RosError(
                describe(
                    "the C node's build",
                    f"the library {lib.library_path} this run loaded",
                    "another one in its place (regenerated meanwhile)",
                    "run the command again",
                )
            )
        tmp = folder / f"{program}.tmp{os.getpid()}"
        objs = folder / f"objects.tmp{os.getpid()}"
        objs.mkdir(exist_ok=True)
        try:
            # each file compiled on its own, as many at once as there are cores, then linked
            units = _compile_commands(cc, ros, srcs, objs, folder, extra_flags)
            _run_all([c for c, _ in units], program, cc)
            extra = _EXTRA_PACKAGES.get(program, ())
            obj_files = [o for _, o in units]
            cmd = _command(cc, lib, ros, obj_files, tmp, folder, extra, extra_flags)
            _run_all([cmd], program, cc)
        except BaseException:
            tmp.unlink(missing_ok=True)  # a half-written program is never left behind
            raise
        finally:
            shutil.rmtree(objs, ignore_errors=True)
        if not tmp.is_file():
            raise RosError(
                describe(
                    "the C node's build",
                    f"a linked {program}",
                    "no file after the linker's exit 0",
                    "run the command again",
                )
            )
        compile_lines = [shlex.join(c) for c, _ in units]
        (folder / "build.json").write_text(
            json.dumps({**inputs, "compile": compile_lines, "command": shlex.join(cmd)}, indent=1)
        )
        tmp.replace(exe)
    return CNodeBuild(exe, key, True)


def _compile_commands(
    cc: str,
    ros: RosPaths,
    srcs: list[Path],
    obj_dir: Path,
    gen_dir: Path,
    flags: tuple[str, ...] = (),
) -> list[tuple[list[str], Path]]:
    """Each source's compile command (``-c``, to an object in ``obj_dir``) against the
    headers of this package, of the library copied into ``gen_dir`` and of the wheels, with
    :data:`CNODE_CFLAGS` and the extra ``flags``; and its object."""
    out = []
    for src in srcs:
        obj = obj_dir / f"{src.stem}.o"
        includes = [f"-I{d}" for d in (C_DIR, gen_dir, *ros.include)]
        out.append(([cc, *CNODE_CFLAGS, *flags, "-c", str(src), *includes, "-o", str(obj)], obj))
    return out


def _run_all(commands: list[list[str]], program: str, cc: str) -> None:
    """Run ``commands`` (compiler calls), as many at once as this machine has cores.

    Raises:
        RosError: one failed (its first errors, not the warnings after them).
    """
    from concurrent.futures import ThreadPoolExecutor

    def one(cmd: list[str]) -> subprocess.CompletedProcess[str]:
        return subprocess.run(cmd, capture_output=True, text=True)

    with ThreadPoolExecutor(max_workers=max(1, min(len(commands), os.cpu_count() or 1))) as pool:
        done = list(pool.map(one, commands))
    for proc in done:
        if proc.returncode != 0:
            checkpoint()  # signals are held in the lock: a Ctrl-C stopped cc, say that
            said = (proc.stderr or proc.stdout).strip().splitlines()
            errors = [ln for ln in said if "error" in ln.lower()]
            tail = " | ".join(errors[:3] or said[-3:])
            raise RosError(
                describe(
                    "the C node's build",
                    f"a compiled {program}",
                    f"{cc} exit {proc.returncode}: {tail}",
                    "check the compiler and the [ros] extra, or run amsfe node --impl python",
                )
            )


def external_build(exe: Path, option: str) -> CNodeBuild:
    """A program built elsewhere (``cmake --build`` or ``colcon build`` of
    ``ros/c/CMakeLists.txt``), named by ``option`` (``--node-exe``, ``--arm-exe``), run
    instead of the wheel build.

    Raises:
        ConfigError: ``exe`` is not an executable file.
    """
    if not (exe.is_file() and os.access(exe, os.X_OK)):
        program = "amsfe_node" if option == "--node-exe" else "amsfe_arm"
        raise ConfigError(
            describe(
                option,
                f"an executable {program}",
                str(exe),
                f"give the {program} of cmake --build (docs/live-control.md)",
            )
        )
    return CNodeBuild(exe, "external", False)


def _compiler_line(cc: str) -> str:
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        raise RosError(
            describe("C compiler", f"a working {cc!r}", str(exc), "install gcc or set $CC")
        ) from exc
    return out.stdout.splitlines()[0] if out.stdout else cc


def _command(
    cc: str,
    lib: ModelLibrary,
    ros: RosPaths,
    objects: list[Path],
    out: Path,
    gen_dir: Path,
    extra: tuple[str, ...] = (),
    flags: tuple[str, ...] = (),
) -> list[str]:
    """The link command of the node's ``objects`` (:func:`_compile_commands`) against the
    library copied into ``gen_dir`` (the node's folder), linking the message packages
    ``extra`` too, with the extra compiler and linker ``flags`` (:data:`EXTRA_FLAGS_ENV`)
    after :data:`CNODE_CFLAGS`."""
    name = lib.library_path.name.removeprefix("lib").removesuffix(".so")
    libs = ["rcl", "rcl_lifecycle", "rcutils", "rmw", "rosidl_runtime_c"]
    for pkg in (*_MSG_PACKAGES, *extra):
        libs += [f"{pkg}__rosidl_generator_c", f"{pkg}__rosidl_typesupport_c"]
    rpaths = [gen_dir, ros.lib, *ros.bundled]
    cmd = [cc, *CNODE_CFLAGS, *flags, *map(str, objects)]
    cmd += [f"-L{gen_dir}", f"-l{name}", f"-L{ros.lib}", *(f"-l{x}" for x in libs), "-lm"]
    cmd += ["-Wl,--disable-new-dtags", *(f"-Wl,-rpath,{d}" for d in rpaths)]
    # the Python type support librcl's wheel links: functions bound lazily (never called),
    # its two data symbols defined by amsfe_pystub.c and exported to the libraries
    cmd += ["-Wl,--allow-shlib-undefined", "-Wl,-z,lazy"]
    cmd += [f"-Wl,--export-dynamic-symbol={s}" for s in _PY_DATA_SYMBOLS]
    return [*cmd, "-o", str(out)]


def run_program(
    exe: Path,
    params: Path,
    ros_args: tuple[str, ...],
    domain_id: int | None,
    env_extra: dict[str, str] | None = None,
) -> tuple[int, KeyboardInterrupt | None]:
    """Run a built program (``exe PARAMS [--ros-args ...]``) in this process's environment
    (the default middleware, lazily bound symbols, ``domain_id``), its output on this
    process's stdout, forwarding Ctrl-C / SIGTERM to it; waits for it.

    Returns:
        Its exit code, and the interrupt this process received meanwhile (None: none).
    """
    from amsfe_sym.ros.middleware import DEFAULT_RMW

    env = dict(os.environ)
    env.setdefault("RMW_IMPLEMENTATION", DEFAULT_RMW)
    env.pop("LD_BIND_NOW", None)  # the Python type support is bound lazily (module doc)
    env.update(env_extra or {})
    if domain_id is not None:
        env["ROS_DOMAIN_ID"] = str(domain_id)
    cmd = [str(exe), str(params)]
    if ros_args:
        cmd += ["--ros-args", *ros_args]
    sys.stdout.flush()
    proc = subprocess.Popen(cmd, env=env)
    interrupt: KeyboardInterrupt | None = None
    while True:
        try:
            return proc.wait(), interrupt
        except KeyboardInterrupt as exc:  # Ctrl-C / SIGTERM of this process
            interrupt = exc
            sig = signal.SIGINT if type(exc) is KeyboardInterrupt else signal.SIGTERM
            if proc.poll() is None:
                proc.send_signal(sig)
