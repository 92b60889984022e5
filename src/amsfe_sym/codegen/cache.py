"""The build cache: where libraries go, the compiler and its flags, the content hash that
decides whether a library is reused, the build lock, and the cleaning of temporary folders
left by killed builds.

The hash covers the URDF and spec bytes, the locked joints, the source of the modules that
build the symbols and the hand-written C compiled into every library (so a change in how we
generate invalidates old output), the CasADi and Pinocchio versions, and the compiler with its
flags.  It guards against accidents (an edited spec, a new toolkit, another compiler), not
against tampering: a file changed on purpose together with its manifest is not detected.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import platform
import shlex
import subprocess
import time
from collections.abc import Iterator, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

from amsfe_sym import __version__
from amsfe_sym.core.folders import STALE_TMP_SECONDS, clean_stale_tmp, replace_dir
from amsfe_sym.core.interrupts import DeferredSignals
from amsfe_sym.errors import CodegenError, describe
from amsfe_sym.load.spec import RobotSpec
from amsfe_sym.runtime.library import file_sha256

__all__ = [
    "ALL_PARTS",
    "DEFAULT_CFLAGS",
    "MANIFEST",
    "STALE_TMP_SECONDS",
    "build_lock",
    "cached_dir",
    "cflags",
    "check_parts",
    "clean_stale_tmp",
    "compiler",
    "content_hash",
    "default_out_dir",
    "manifest_of",
    "replace_dir",
]

DEFAULT_CFLAGS: tuple[str, ...] = ("-O1", "-fPIC", "-shared")
MANIFEST = "manifest.json"
#: Modules whose source decides what is generated (hashed into the cache key; globs are
#: relative to the package folder, so a new module of a stage is hashed without a change here).
_GENERATOR_MODULES = (
    "load/*.py",
    "codegen/*.py",
    "symbolic/*.py",
    "runtime/c/*.c",
    "runtime/c/*.h",
)
#: Every function group (see :data:`amsfe_sym.symbolic.model.PARTS`, kept equal).
ALL_PARTS: tuple[str, ...] = ("model", "control", "estimator")

#: The package folder (``src/amsfe_sym``): the globs above are relative to it.
_PACKAGE = Path(__file__).resolve().parent.parent


def check_parts(parts: Sequence[str]) -> tuple[str, ...]:
    """``parts`` in canonical order, with ``model`` always in."""
    bad = sorted(set(parts) - set(ALL_PARTS))
    if bad:
        raise CodegenError(
            describe("generate parts", f"names among {list(ALL_PARTS)}", f"{bad}", "fix them")
        )
    return tuple(k for k in ALL_PARTS if k == "model" or k in parts)


def default_out_dir() -> Path:
    """Where libraries go by default: ``$AMSFE_GENERATED_DIR``, else ``generated/`` in the
    current directory (as ``runs/``), wherever the package is installed: a command run in
    another folder no longer writes into the checkout it was installed from
    (docs/api.md, "Where files go")."""
    env = os.environ.get("AMSFE_GENERATED_DIR")
    if env:
        return Path(env)
    return Path.cwd() / "generated"


def compiler() -> str:
    """The C compiler: ``$CC`` or ``cc``."""
    return os.environ.get("CC", "cc")


def cflags(extra: Sequence[str] | None = None) -> list[str]:
    """Compiler flags: ``$AMSFE_CFLAGS`` (shell-split) or the defaults, plus ``extra``."""
    env = os.environ.get("AMSFE_CFLAGS")
    flags = shlex.split(env) if env else list(DEFAULT_CFLAGS)
    for required in ("-fPIC", "-shared"):
        if required not in flags:
            flags.append(required)
    return flags + list(extra or ())


def _compiler_version(cc: str) -> str:
    try:
        out = subprocess.run([cc, "--version"], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError) as exc:
        raise CodegenError(
            describe("C compiler", f"a working {cc!r}", f"error {exc}", "install gcc or set $CC")
        ) from exc
    return out.stdout.splitlines()[0] if out.stdout else cc


#: Flags that tie the code to the build machine's CPU: with one of them the cache key holds
#: the CPU kind (:func:`cpu_kind`), so a library built on another CPU is rebuilt, not reused.
NATIVE_FLAGS = ("-march=native", "-mcpu=native", "-mtune=native")


def cpu_kind(cc: str, flags: Sequence[str]) -> str | None:
    """The CPU kind ``flags`` compile for, or None when they name no ``native`` target.

    The compiler's own resolution of ``-march=native`` (``cc -march=native -Q --help=target``:
    its ``-march=`` / ``-mcpu=`` line, e.g. ``znver3``) and the CPU's model name from
    ``/proc/cpuinfo`` (when it exists): two CPUs that gcc resolves alike still get separate
    cache entries when their names differ.
    """
    native = [f for f in flags if f in NATIVE_FLAGS]
    if not native:
        return None
    kind = []
    try:
        out = subprocess.run(
            [cc, *native, "-Q", "--help=target"], capture_output=True, text=True, check=True
        ).stdout
        lines = [ln.split() for ln in out.splitlines()]
        kind += [ln[1] for ln in lines if len(ln) == 2 and ln[0] in ("-march=", "-mcpu=")]
    except (OSError, subprocess.CalledProcessError):
        pass
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        names = [
            ln.split(":", 1)[1].strip()
            for ln in cpuinfo.read_text().splitlines()
            if ln.startswith(("model name", "Model"))
        ]
        kind += names[:1]
    return " / ".join(kind) or platform.processor() or platform.machine()


def content_hash(
    spec: RobotSpec, flags: Sequence[str], parts: Sequence[str] = ALL_PARTS
) -> tuple[str, dict[str, Any]]:
    """The cache key of ``spec`` built with ``flags`` (and ``parts``), and what went into it."""
    src = _PACKAGE
    gen = hashlib.sha256()
    for pattern in _GENERATOR_MODULES:
        for path in sorted(src.glob(pattern)):
            gen.update(path.read_bytes())
    cc = compiler()
    inputs: dict[str, Any] = {
        "robot": spec.fingerprint(),
        "generator_source": gen.hexdigest(),
        "amsfe_sym": __version__,
        "casadi": metadata.version("casadi"),
        "pinocchio": metadata.version("pin") if _has_dist("pin") else "unknown",
        "compiler": _compiler_version(cc),
        "cflags": list(flags),
        "machine": platform.machine(),
    }
    if tuple(parts) != ALL_PARTS:  # (absent for a full library: its key is unchanged)
        inputs["parts"] = list(parts)
    cpu = cpu_kind(cc, flags)
    if cpu is not None:  # (absent without -march=native: those keys are unchanged)
        inputs["cpu"] = cpu
    key = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()
    return key, inputs


def _has_dist(name: str) -> bool:
    try:
        metadata.version(name)
    except metadata.PackageNotFoundError:
        return False
    return True


def manifest_of(out_dir: Path) -> dict[str, Any] | None:
    """The manifest in ``out_dir`` as a dict, or None when there is none or it is not a JSON
    object (the cache's checks treat both as no library)."""
    try:
        manifest = json.loads((out_dir / MANIFEST).read_text())
    except (OSError, ValueError):
        return None
    return manifest if isinstance(manifest, dict) else None


def cached_dir(out_dir: Path, key: str) -> Path | None:
    """The library path if ``out_dir`` holds a complete build with hash ``key`` whose
    library still has the sha256 recorded in the manifest (a truncated or damaged ``.so``
    is not reused: it is rebuilt)."""
    manifest = manifest_of(out_dir)
    if manifest is None or manifest.get("content_hash") != key:
        return None
    lib = out_dir / str(manifest.get("library", ""))
    try:
        if not lib.is_file() or file_sha256(lib) != manifest.get("library_sha256"):
            return None
    except OSError:
        return None
    return lib


@contextlib.contextmanager
def build_lock(path: Path, poll: float = 0.05) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (released when the process dies).

    The file is removed afterwards, so a failed or interrupted build leaves nothing behind;
    a process that opened it just before the removal may then build the same library once
    more, which the atomic move into place keeps harmless.

    Ctrl-C and SIGTERM are held from before the file is made until it is removed
    (:class:`~amsfe_sym.core.interrupts.DeferredSignals`), and delivered while the lock is
    awaited (polled every ``poll`` s), at the body's checkpoints, or on leaving: a signal
    that landed between the file's creation and the ``try`` that removes it used to leave
    the lock file behind.  A process interrupted while it waits leaves the file to its
    holder, which removes it.
    """
    with DeferredSignals() as held:
        created = not path.parent.exists()
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a") as fh:
            acquired = False
            try:
                while True:
                    try:
                        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                        acquired = True
                        break
                    except BlockingIOError:
                        held.check()  # Ctrl-C while another build holds it
                        time.sleep(poll)
                held.check()
                yield
            finally:
                if acquired:
                    path.unlink(missing_ok=True)
                    fcntl.flock(fh, fcntl.LOCK_UN)
                if created and not any(path.parent.iterdir()):  # bad input: leave no folder
                    path.parent.rmdir()
