"""Compiling a library: its C files as separate units on every core, then one link.

A library is the generated file (``<robot>.c``) and the hand-written C of ``runtime/c``.  One
``cc`` command over all of them compiled them one after the other on one core; the Panda's
9.8 s of compile were 5.4 s for ``panda.c`` and 4.4 s for the runtime files (2.3 s of them the
O3 kernels), measured unit by unit on a 2-core AMD EPYC (docs/codegen.md).  Here each file
is its own unit (``cc -c``), the units run ``jobs`` at a time (default: the CPUs this process
may use), the largest first, and the objects are linked into the shared library.

The robot-independent units (:data:`SHARED_UNITS`: the estimator kernels, the closed loop
and the watchdogs, which include no generated header) are compiled once per content: their
object is kept in ``<parent>/.objects/<key>.o``, the key a sha256 of the compiler's version,
the flags, the CPU kind when the flags name ``native``, the unit's source and every header of
``runtime/c``.  A later library in the same parent folder (another robot, another
integrator; the test suite builds a dozen) links that object instead of compiling it again.
A damaged or missing object is simply compiled again; the object is written under a
temporary name and moved into place, so a concurrent build never links a partial file.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import subprocess
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from amsfe_sym.core.interrupts import checkpoint
from amsfe_sym.errors import CodegenError, describe

__all__ = [
    "OBJECT_CACHE",
    "RUNTIME_C",
    "SHARED_UNITS",
    "Unit",
    "build_jobs",
    "compile_library",
    "run_commands",
    "runtime_unit",
    "say",
]

#: The hand-written C of the runtime (``runtime/c``).
RUNTIME_C = Path(__file__).resolve().parent.parent / "runtime" / "c"

#: The files of ``runtime/c`` whose object does not depend on the robot.
SHARED_UNITS = ("amsfe_kernels.c", "amsfe_loop.c", "amsfe_watchdog.c")

#: The object cache's folder, in the parent folder of the libraries.
OBJECT_CACHE = ".objects"

#: Seconds between two "still compiling" lines (``progress``).
COMPILE_PROGRESS_S = 5.0


@dataclass(frozen=True)
class Unit:
    """One C file of a library.

    Attributes:
        source: Its path (relative to the build folder, or absolute).
        shared: Robot-independent: its object may come from, and goes to, the object cache.
    """

    source: str
    shared: bool = False


def runtime_unit(name: str) -> Unit:
    """The unit of the file ``name`` of ``runtime/c``, shared when it is in
    :data:`SHARED_UNITS`."""
    return Unit(str(RUNTIME_C / name), shared=name in SHARED_UNITS)


def build_jobs() -> int:
    """Compiler processes at a time: ``$AMSFE_BUILD_JOBS``, else the CPUs this process may
    use (at least 1).

    Raises:
        CodegenError: ``$AMSFE_BUILD_JOBS`` is set but not an integer >= 1 (it used to be
            ignored without a word).
    """
    env = os.environ.get("AMSFE_BUILD_JOBS", "").strip()
    if env:
        if not (env.isdigit() and int(env) > 0):
            raise CodegenError(
                describe(
                    "$AMSFE_BUILD_JOBS",
                    "an integer >= 1 (compiler processes at a time)",
                    repr(os.environ["AMSFE_BUILD_JOBS"]),
                    "export AMSFE_BUILD_JOBS=2, or unset it to use every core",
                )
            )
        return int(env)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def object_key(unit: Path, key_inputs: dict[str, Any]) -> str:
    """The object cache's key of a shared unit (see the module docstring)."""
    h = hashlib.sha256(json.dumps(key_inputs, sort_keys=True).encode())
    h.update(unit.name.encode() + b"\0" + unit.read_bytes())
    for header in sorted(RUNTIME_C.glob("*.h")):
        h.update(header.name.encode() + b"\0" + header.read_bytes())
    return h.hexdigest()


def run_commands(
    cmds: Sequence[Sequence[str]], cwd: Path, progress: bool, name: str, jobs: int = 1
) -> subprocess.CompletedProcess[str]:
    """Run ``cmds`` in ``cwd``, ``jobs`` at a time, in their order.

    The first that fails stops the others; its exit code and messages are returned (else
    those of the last command, exit code 0).  With ``progress``, a line on stderr every
    :data:`COMPILE_PROGRESS_S` seconds while they run (a large arm compiles for seconds).  A
    held Ctrl-C or SIGTERM (:func:`~amsfe_sym.core.interrupts.checkpoint`, polled every
    0.1 s) kills them and is raised."""
    pending = [list(c) for c in cmds]
    running: list[tuple[list[str], subprocess.Popen[str], IO[str]]] = []
    t0 = last = time.perf_counter()
    result = subprocess.CompletedProcess(pending[-1] if pending else [], 0, "", "")
    with contextlib.ExitStack() as files:  # each command's stderr, closed on the way out
        try:
            while pending or running:
                while pending and len(running) < max(1, jobs):
                    cmd = pending.pop(0)
                    log: IO[str] = files.enter_context(tempfile.TemporaryFile("w+"))
                    proc = subprocess.Popen(
                        cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=log, text=True
                    )
                    running.append((cmd, proc, log))
                for item in list(running):
                    done, proc, log = item
                    if proc.poll() is None:
                        continue
                    running.remove(item)
                    log.seek(0)
                    result = subprocess.CompletedProcess(done, proc.returncode, "", log.read())
                    if proc.returncode != 0:
                        _stop(running)
                        return result
                if running:
                    time.sleep(0.1)
                    checkpoint()
                    now = time.perf_counter()
                    if progress and now - last >= COMPILE_PROGRESS_S:
                        last = now
                        say(True, f"[amsfe] {name}: compiling, {now - t0:.0f} s so far")
        except BaseException:
            _stop(running)
            raise
    return result


def _stop(running: list[tuple[list[str], subprocess.Popen[str], IO[str]]]) -> None:
    """Kill and reap the commands still running."""
    for _, proc, _err in running:
        proc.kill()
        proc.wait()
    running.clear()


def compile_library(
    units: Sequence[Unit],
    cc: str,
    flags: Sequence[str],
    cwd: Path,
    libname: str,
    key_inputs: dict[str, Any],
    object_cache: Path | None,
    progress: bool,
    name: str,
    reuse: bool = True,
) -> subprocess.CompletedProcess[str]:
    """Compile ``units`` in ``cwd`` (``-I.``) and link them into ``cwd/libname``.

    Args:
        units: The C files, the generated one first (the largest: it starts first).
        cc: The compiler.
        flags: Its flags (the library's: ``-O1 -fPIC -shared`` by default).
        cwd: The build folder.
        libname: The shared library's file name.
        key_inputs: What the library's cache key holds of the toolchain (compiler version,
            flags, machine, CPU kind): the shared units' object key includes it.
        object_cache: Folder of the shared units' objects (None: always compile).
        progress: Print "compiling" lines to stderr.
        name: The robot's name, for those lines.
        reuse: Link cached shared objects (False: compile them, and refresh the cache).

    Returns:
        The failed compile or link (its exit code and messages), else the link's.
    """
    compiles: list[list[str]] = []
    objects: list[str] = []
    to_cache: list[tuple[Path, Path]] = []
    for i, unit in enumerate(units):
        src = Path(unit.source)
        obj = f"unit{i}_{src.stem}.o"
        cached = None
        if unit.shared and object_cache is not None:
            cached = object_cache / f"{src.stem}-{object_key(src, key_inputs)[:32]}.o"
            if reuse and cached.is_file() and cached.stat().st_size > 0:
                objects.append(str(cached))
                continue
        compiles.append([cc, *flags, "-I.", "-c", unit.source, "-o", obj])
        objects.append(obj)
        if cached is not None:
            to_cache.append((cwd / obj, cached))
    say(
        progress,
        f"[amsfe] {name}: compiling ({len(compiles)} of {len(units)} unit(s), "
        f"{len(units) - len(compiles)} from the object cache, {build_jobs()} at a time: "
        f"{' '.join([cc, *flags])} -c ...)",
    )
    if compiles:
        proc = run_commands(compiles, cwd, progress, name, build_jobs())
        if proc.returncode != 0:
            return proc
    for built, dest in to_cache:
        _store(built, dest)
    link = [cc, *flags, "-o", libname, *objects, "-lm"]
    return run_commands([link], cwd, progress, name)


def _store(built: Path, dest: Path) -> None:
    """Copy an object into the cache under a temporary name, then move it into place (best
    effort: a full disk or a read-only folder only costs a compile next time)."""
    tmp = None
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.stem}-", suffix=".tmp", dir=dest.parent)
        os.close(fd)
        shutil.copyfile(built, tmp)
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would hide it from the folder's other users
        os.replace(tmp, dest)
    except OSError:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def say(on: bool, msg: str) -> None:
    """``msg`` on stderr when ``on`` (generate's progress lines)."""
    if on:
        import sys

        print(msg, file=sys.stderr, flush=True)
