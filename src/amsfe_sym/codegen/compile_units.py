"""Compiling a library: its C files as separate units on every core, then one link.

A library is the generated file (``<robot>.c``) and the hand-written C of ``runtime/c``.  One
``cc`` command over all of them compiled them one after the other on one core; the Panda's
9.8 s of compile were 5.4 s for ``panda.c`` and 4.4 s for the runtime files (2.3 s of them the
O3 kernels), measured unit by unit on a 2-core AMD EPYC (docs/explanation/codegen.md).  Here each
file
is its own unit (``cc -c``), the units run ``jobs`` at a time (default: the CPUs this process
may use), the largest first, and the objects are linked into the shared library.

Every unit of a library is compiled once per content: its object is kept in
``<parent>/.objects/<label>-<key>.o``, the key a sha256 of the compiler's version, the flags,
the CPU kind when the flags name ``native``, the unit's source and every header it can
include (those of ``runtime/c``, and the build folder's ``amsfe_model_config.h``), not the
file's name.  A later library in the same parent folder
links that object instead of compiling it again: the robot-independent units
(:data:`SHARED_UNITS`: the estimator kernels, the closed loop and the watchdogs) for every
robot; the robot's own units when their bytes are another library's, e.g. the same model
under another name (a sweep's ``paper_2link_r<tag>_rk4``, whose parameters are data, is
``paper_2link_rk4``'s C; the tutorial's ``my_arm`` is ``ur5_rk4``'s), the generated C's
symbol prefix being the same for every robot (:data:`GENERATED_PREFIX`).  A damaged or
missing object is simply compiled again; the object is written under a temporary name and
moved into place, so a concurrent build never links a partial file.  An object unused for
:data:`OBJECT_MAX_AGE_S` is removed when another is stored.
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
    "GENERATED_PREFIX",
    "OBJECT_CACHE",
    "OBJECT_MAX_AGE_S",
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
SHARED_UNITS = (
    "amsfe_kernels.c",
    "amsfe_loop.c",
    "amsfe_ctrl.c",
    "amsfe_blend.c",
    "amsfe_watchdog.c",
)

#: The object cache's folder, in the parent folder of the libraries.
OBJECT_CACHE = ".objects"

#: The symbol prefix of CasADi's helpers in every generated C file (``amsfe_cg_copy``, ...;
#: CasADi's default is the file's name): one model's C is then the same bytes whatever the
#: robot's name, and its object is compiled once (the contract's functions, ``transition``
#: and the others, carry no prefix in any library).
GENERATED_PREFIX = "amsfe_cg"

#: Seconds after its last use that a cached object is removed (30 days).
OBJECT_MAX_AGE_S = 30 * 24 * 3600.0

#: Seconds between two "still compiling" lines (``progress``).
COMPILE_PROGRESS_S = 5.0


@dataclass(frozen=True)
class Unit:
    """One C file of a library.

    Attributes:
        source: Its path (relative to the build folder, or absolute).
        shared: Its object may come from, and goes to, the object cache (keyed by its
            content and the headers it can include, not its name).
        local: It includes headers of the build folder (the generated ones): their bytes
            are in its key too (the robot-independent units include only ``runtime/c``'s).
        label: Its objects' name in the cache (default: the file's stem).
    """

    source: str
    shared: bool = False
    local: bool = False
    label: str = ""


def runtime_unit(name: str, local: bool = False) -> Unit:
    """The unit of the file ``name`` of ``runtime/c``, its object cached: robot-independent
    when it is in :data:`SHARED_UNITS`, else ``local`` (it includes the build folder's
    ``amsfe_model_config.h``: its key holds that folder's headers)."""
    shared = name in SHARED_UNITS
    return Unit(str(RUNTIME_C / name), shared=shared or local, local=local and not shared)


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


def object_key(unit: Path, key_inputs: dict[str, Any], build: Path | None = None) -> str:
    """The object cache's key of a shared unit: the toolchain (``key_inputs``), the unit's
    bytes, those of every header of ``runtime/c`` and, with ``build``, those of the build
    folder's headers that the unit or a header names (what an ``#include "x.h"`` can
    read: ``amsfe_model_config.h``; not the generated ``<robot>.h``, which no unit includes,
    so that the same model under another name has the same key)."""
    h = hashlib.sha256(json.dumps(key_inputs, sort_keys=True).encode())
    source = unit.read_bytes()
    h.update(b"unit\0" + source)
    runtime = sorted(RUNTIME_C.glob("*.h"))
    local = sorted(build.glob("*.h")) if build is not None else []
    texts = [source] + [p.read_bytes() for p in runtime + local]
    for header in runtime:
        h.update(b"runtime/" + header.name.encode() + b"\0" + header.read_bytes())
    for header in local:
        if any(header.name.encode() in t for t in texts):
            h.update(b"build/" + header.name.encode() + b"\0" + header.read_bytes())
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
            path = src if src.is_absolute() else cwd / src
            key = object_key(path, key_inputs, cwd if unit.local else None)
            cached = object_cache / f"{unit.label or src.stem}-{key[:32]}.o"
            if reuse and cached.is_file() and cached.stat().st_size > 0:
                with contextlib.suppress(OSError):
                    os.utime(cached)  # used: kept another OBJECT_MAX_AGE_S
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
    if to_cache and object_cache is not None:
        _prune(object_cache)
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


def _prune(cache: Path, max_age_s: float = OBJECT_MAX_AGE_S) -> None:
    """Remove the cached objects unused for ``max_age_s`` (best effort; a build that uses
    one touches it first)."""
    now = time.time()
    for obj in cache.glob("*.o"):
        with contextlib.suppress(OSError):
            if now - obj.stat().st_mtime > max_age_s:
                obj.unlink()


def say(on: bool, msg: str) -> None:
    """``msg`` on stderr when ``on`` (generate's progress lines)."""
    if on:
        import sys

        print(msg, file=sys.stderr, flush=True)
