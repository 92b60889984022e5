"""Code generation: symbolic functions -> C source + header + shared library + manifest.

One shared library per robot in ``generated/<name>/``.  Generation is cached by content:
the hash covers the URDF and spec bytes, the locked joints, the source of the modules that
build the symbols (so a change in how we generate invalidates old output), the CasADi and
Pinocchio versions, and the compiler with its flags.  An unchanged robot is neither
regenerated nor recompiled; the cache check reads only files, never Pinocchio.

Output is written to a temporary folder and moved into place only when the library has
compiled and loaded, so bad input, a failed build or Ctrl-C leaves ``generated/`` as it was.
The manifest records the library's own sha256: the cache reuses, and the runtime loads, only
a library whose bytes still match it (a truncated or damaged ``.so`` is rebuilt here and
refused by :class:`~amsfe_sym.runtime.library.ModelLibrary`).  Hidden temporary folders left
by a killed run (its pid gone, or older than an hour) are removed by the next build.

Compiler flags: ``-O1`` by default (see docs/codegen.md for the measurements behind it);
override with ``$AMSFE_CFLAGS`` or ``--cflags``.  ``-march=native`` ties the library to
the CPU; it is allowed, and since the flags are hashed, a changed flag rebuilds.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import json
import math
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from importlib import metadata
from pathlib import Path
from typing import Any

import casadi as ca

from amsfe_sym import __version__
from amsfe_sym.errors import CodegenError, describe
from amsfe_sym.runtime.library import ModelLibrary, file_sha256
from amsfe_sym.scenario import Scenario, camera_timing
from amsfe_sym.spec import RobotSpec, load_spec

__all__ = [
    "DEFAULT_CFLAGS",
    "GenerateResult",
    "cached_library",
    "clean_stale_tmp",
    "content_hash",
    "default_out_dir",
    "generate",
    "library_for",
    "load_library",
]

DEFAULT_CFLAGS: tuple[str, ...] = ("-O1", "-fPIC", "-shared")
MANIFEST = "manifest.json"
#: Modules whose source decides what is generated (hashed into the cache key; globs are
#: relative to the package folder, so a new module of a stage is hashed without a change here).
_GENERATOR_MODULES = (
    "spec.py",
    "load/*.py",
    "codegen.py",
    "symbolic/*.py",
    "runtime/c/amsfe_runtime.c",
    "runtime/c/amsfe_runtime.h",
    "runtime/c/amsfe_loop.c",
    "runtime/c/amsfe_loop.h",
    "runtime/c/amsfe_internal.h",
)
#: Every function group (see :data:`amsfe_sym.symbolic.model.PARTS`, kept equal).
ALL_PARTS: tuple[str, ...] = ("model", "control", "estimator")


def _check_parts(parts: Sequence[str]) -> tuple[str, ...]:
    """``parts`` in canonical order, with ``model`` always in."""
    bad = sorted(set(parts) - set(ALL_PARTS))
    if bad:
        raise CodegenError(
            describe("generate parts", f"names among {list(ALL_PARTS)}", f"{bad}", "fix them")
        )
    return tuple(k for k in ALL_PARTS if k == "model" or k in parts)


#: The hand-written C glue of the compiled estimators, built into every library.
_RUNTIME_C = Path(__file__).resolve().parent / "runtime" / "c"


@dataclass(frozen=True)
class GenerateResult:
    """What :func:`generate` did.

    Attributes:
        out_dir: ``generated/<name>/``.
        manifest_path: Its ``manifest.json``.
        library_path: The shared library.
        reused: True when the cache matched and nothing was rebuilt.
        seconds: Wall time of the call [s].
        timings: Per-stage wall times [s] (load, symbolic, codegen, compile) when built.
    """

    out_dir: Path
    manifest_path: Path
    library_path: Path
    reused: bool
    seconds: float
    timings: dict[str, float]


def default_out_dir() -> Path:
    """``$AMSFE_GENERATED_DIR``, else the repository's ``generated/``, else ``./generated``."""
    env = os.environ.get("AMSFE_GENERATED_DIR")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parent.parent.parent
    if (repo / "pyproject.toml").is_file() and (repo / "generated").is_dir():
        return repo / "generated"
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


def content_hash(
    spec: RobotSpec, flags: Sequence[str], parts: Sequence[str] = ALL_PARTS
) -> tuple[str, dict[str, Any]]:
    """The cache key of ``spec`` built with ``flags`` (and ``parts``), and what went into it."""
    src = Path(__file__).resolve().parent
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
    key = hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()
    return key, inputs


def _has_dist(name: str) -> bool:
    try:
        metadata.version(name)
    except metadata.PackageNotFoundError:
        return False
    return True


def _cached(out_dir: Path, key: str) -> Path | None:
    """The library path if ``out_dir`` holds a complete build with hash ``key`` whose
    library still has the sha256 recorded in the manifest (a truncated or damaged ``.so``
    is not reused: it is rebuilt)."""
    mpath = out_dir / MANIFEST
    try:
        manifest = json.loads(mpath.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(manifest, dict) or manifest.get("content_hash") != key:
        return None
    lib = out_dir / str(manifest.get("library", ""))
    try:
        if not lib.is_file() or file_sha256(lib) != manifest.get("library_sha256"):
            return None
    except OSError:
        return None
    return lib


#: A hidden temporary build folder older than this is left over from a killed run [s].
STALE_TMP_SECONDS = 3600.0


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


def clean_stale_tmp(parent: Path, name: str, max_age: float = STALE_TMP_SECONDS) -> list[Path]:
    """Remove ``parent/.<name>-<pid>-*`` and ``parent/.<name>.old-<pid>-*`` folders left by a
    killed :func:`generate`: those whose process is gone, or older than ``max_age`` [s].

    Returns:
        The folders removed.
    """
    removed = []
    now = time.time()
    for prefix in (f".{name}-", f".{name}.old-"):
        for d in parent.glob(prefix + "*"):
            pid_text = d.name[len(prefix) :].partition("-")[0]
            if not d.is_dir() or not pid_text.isdigit():  # not ours (another robot's name)
                continue
            try:
                age = now - d.stat().st_mtime
            except OSError:
                continue
            dead = not _pid_alive(int(pid_text))
            if dead or age > max_age:
                shutil.rmtree(d, ignore_errors=True)
                removed.append(d)
    return removed


def cached_library(
    robot: str | os.PathLike[str] | RobotSpec = "paper_2link",
    out: str | os.PathLike[str] | None = None,
    lock: dict[str, float] | None = None,
    extra_cflags: Sequence[str] | None = None,
    parts: Sequence[str] = ALL_PARTS,
) -> GenerateResult | None:
    """The verified cached library :func:`generate` would reuse, or None (builds nothing)."""
    t_start = time.perf_counter()
    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    if lock:
        spec = spec.with_locked(lock)
    parts = _check_parts(parts)
    key, _ = content_hash(spec, cflags(extra_cflags), parts)
    parent = Path(out) if out is not None else default_out_dir()
    out_dir = parent / (spec.name if parts == ALL_PARTS else f"{spec.name}-{'-'.join(parts)}")
    lib = _cached(out_dir, key)
    if lib is None:
        return None
    return GenerateResult(out_dir, out_dir / MANIFEST, lib, True, time.perf_counter() - t_start, {})


def generate(
    robot: str | os.PathLike[str] | RobotSpec = "paper_2link",
    out: str | os.PathLike[str] | None = None,
    lock: dict[str, float] | None = None,
    extra_cflags: Sequence[str] | None = None,
    force: bool = False,
    progress: bool = False,
    parts: Sequence[str] = ALL_PARTS,
) -> GenerateResult:
    """Generate (or reuse) the compiled model library of a robot.

    Args:
        robot: Robot name, folder, ``robot.toml``, URDF path, or a spec.
        out: Parent folder; output goes to ``<out>/<name>/`` (default :func:`default_out_dir`).
        lock: Extra joints to lock, name -> value [rad or m].
        extra_cflags: Extra compiler flags (hashed into the cache key).
        force: Rebuild even if the cache matches.
        progress: Print stage timings to stderr.
        parts: Function groups to build, among ``model`` (always), ``control`` and
            ``estimator``.  A partial library goes to ``<out>/<name>-<parts>/`` so it never
            evicts the full one from the cache (checks of third-party arms need the model
            only, and skip most of the compile time).

    Returns:
        A :class:`GenerateResult`.

    Raises:
        UrdfError, SpecError, ModelError: bad input (nothing is written).
        CodegenError: the compiler failed (nothing is replaced).
    """
    t_start = time.perf_counter()
    spec = robot if isinstance(robot, RobotSpec) else load_spec(robot)
    if lock:
        spec = spec.with_locked(lock)
    flags = cflags(extra_cflags)
    parts = _check_parts(parts)
    key, hash_inputs = content_hash(spec, flags, parts)
    parent = Path(out) if out is not None else default_out_dir()
    out_dir = parent / (spec.name if parts == ALL_PARTS else f"{spec.name}-{'-'.join(parts)}")
    if not force:
        lib = _cached(out_dir, key)
        if lib is not None:
            return GenerateResult(
                out_dir, out_dir / MANIFEST, lib, True, time.perf_counter() - t_start, {}
            )

    # one build per library at a time, across processes (pytest-xdist workers, study
    # workers, two shells): the others wait and then find it in the cache
    with _build_lock(parent / f".{out_dir.name}.lock"):
        if not force:
            lib = _cached(out_dir, key)
            if lib is not None:
                return GenerateResult(
                    out_dir, out_dir / MANIFEST, lib, True, time.perf_counter() - t_start, {}
                )
        return _build(spec, parts, flags, key, hash_inputs, parent, out_dir, progress, t_start)


def _build(
    spec: RobotSpec,
    parts: tuple[str, ...],
    flags: list[str],
    key: str,
    hash_inputs: dict[str, Any],
    parent: Path,
    out_dir: Path,
    progress: bool,
    t_start: float,
) -> GenerateResult:
    """Load, build the symbols, generate C, compile and move into ``out_dir`` (see
    :func:`generate`)."""
    # heavy imports only when building
    from amsfe_sym.load import load_robot
    from amsfe_sym.symbolic.model import build_functions

    timings: dict[str, float] = {}
    t = time.perf_counter()
    robot_obj = load_robot(spec)
    timings["load"] = time.perf_counter() - t
    t = time.perf_counter()
    model = build_functions(robot_obj, parts)
    timings["symbolic"] = time.perf_counter() - t
    _say(progress, f"[amsfe] {spec.name}: symbolic model built in {timings['symbolic']:.2f} s")

    parent.mkdir(parents=True, exist_ok=True)
    clean_stale_tmp(parent, spec.name)
    tmp = Path(tempfile.mkdtemp(prefix=f".{spec.name}-{os.getpid()}-", dir=parent))
    tmp.chmod(0o755)
    try:
        t = time.perf_counter()
        cname = f"{spec.name}.c"
        gen = ca.CodeGenerator(cname, {"with_header": True, "with_mem": False})
        for f in model.functions.values():
            for i in range(f.n_out()):  # the binding and the C contract need dense outputs
                if not f.sparsity_out(i).is_dense():
                    raise CodegenError(
                        describe(
                            f"{f.name()} output {f.name_out(i)}",
                            "a dense output",
                            "a sparse one",
                            "wrap the expression in ca.densify",
                        )
                    )
            gen.add(f)
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            gen.generate()
        finally:
            os.chdir(cwd)
        timings["codegen"] = time.perf_counter() - t
        t = time.perf_counter()
        libname = f"lib{spec.name}.so"
        glue = []
        if "estimator" in parts:  # the C glue calls the est_* functions
            shutil.copy(_RUNTIME_C / "amsfe_runtime.h", tmp)
            glue = [str(_RUNTIME_C / "amsfe_runtime.c")]
        if set(parts) == set(ALL_PARTS):  # the loop calls the laws, the plant, the estimators
            shutil.copy(_RUNTIME_C / "amsfe_loop.h", tmp)
            glue.append(str(_RUNTIME_C / "amsfe_loop.c"))
        cmd = [compiler(), *flags, "-I.", "-o", libname, cname, *glue, "-lm"]
        _say(progress, f"[amsfe] {spec.name}: compiling ({' '.join(cmd)})")
        proc = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True)
        if proc.returncode != 0:
            raise CodegenError(
                describe(
                    f"compiling {cname}",
                    "a successful build",
                    f"exit code {proc.returncode}: {proc.stderr[-2000:]}",
                    "check the compiler and $AMSFE_CFLAGS",
                )
            )
        timings["compile"] = time.perf_counter() - t
        try:
            ctypes.CDLL(str(tmp / libname))
        except OSError as exc:
            raise CodegenError(
                describe(
                    f"loading {libname}",
                    "a loadable library",
                    str(exc),
                    "check the compiler and $AMSFE_CFLAGS (the build produced an unusable .so)",
                )
            ) from exc
        manifest = _manifest(model, key, hash_inputs, libname, cname, timings)
        manifest["library_sha256"] = file_sha256(tmp / libname)
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
        _replace_dir(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _say(progress, f"[amsfe] {spec.name}: compiled in {timings['compile']:.2f} s -> {out_dir}")
    return GenerateResult(
        out_dir,
        out_dir / MANIFEST,
        out_dir / f"lib{spec.name}.so",
        False,
        time.perf_counter() - t_start,
        timings,
    )


@contextlib.contextmanager
def _build_lock(path: Path) -> Iterator[None]:
    """An exclusive advisory lock on ``path`` (released when the process dies).

    The file is removed afterwards, so a failed or interrupted build leaves nothing behind;
    a process that opened it just before the removal may then build the same library once
    more, which the atomic move into place keeps harmless.
    """
    created = not path.parent.exists()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            path.unlink(missing_ok=True)
            fcntl.flock(fh, fcntl.LOCK_UN)
            if created and not any(path.parent.iterdir()):  # bad input: leave no folder
                path.parent.rmdir()


def _replace_dir(new: Path, target: Path) -> None:
    """Move ``new`` to ``target`` replacing any old content, as atomically as rename allows."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old-{os.getpid()}-{time.time_ns()}")
        target.rename(old)
    new.rename(target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _say(on: bool, msg: str) -> None:
    if on:
        import sys

        print(msg, file=sys.stderr, flush=True)


def _io(name: str, shape: tuple[int, int]) -> dict[str, Any]:
    """Manifest entry of one input or output: name, shape, and whether it is a matrix
    (a jacobian with one column is still a matrix) or a vector."""
    from amsfe_sym.symbolic.model import MATRIX_OUTPUTS

    return {"name": name, "shape": list(shape), "matrix": name in MATRIX_OUTPUTS or shape[1] > 1}


def _manifest(
    model: Any,
    key: str,
    hash_inputs: dict[str, Any],
    libname: str,
    cname: str,
    timings: dict[str, float],
) -> dict[str, Any]:
    robot = model.robot
    cam = robot.camera
    fns = {}
    for name, f in model.functions.items():
        fns[name] = {
            "inputs": [_io(f.name_in(i), f.size_in(i)) for i in range(f.n_in())],
            "outputs": [_io(f.name_out(i), f.size_out(i)) for i in range(f.n_out())],
        }
    n, p = robot.n, robot.p
    return {
        "name": robot.name,
        "library": libname,
        "source": cname,
        "header": cname[:-2] + ".h",
        "runtime_header": "amsfe_runtime.h" if "est_predict" in model.functions else None,
        "loop_header": "amsfe_loop.h"
        if "control_amsfe" in model.functions and "est_predict" in model.functions
        else None,
        "urdf": str(robot.spec.urdf),
        "spec": None if robot.spec.spec_path is None else str(robot.spec.spec_path),
        "joints": [j.name for j in robot.joints],
        "joint_kinds": [j.kind for j in robot.joints],
        "locked": dict(robot.spec.model.locked),
        "n": n,
        "p": p,
        "N": 4 * n + p,
        "theta": [
            {
                "name": b.spec.name,
                "kind": b.spec.kind,
                "target": b.spec.target,
                "offset": list(b.spec.offset),
                "true": b.spec.true,
                "initial": b.spec.initial,
                "unit": "N m/rad" if b.spec.kind == "joint_stiffness" else "kg",
            }
            for b in robot.theta
        ],
        "tracked_frame": robot.tracked_frame,
        "tracked_offset": robot.tracked_offset.tolist(),
        "T": robot.spec.model.T,
        "integrator": robot.spec.model.integrator,
        "inverse_iterations": robot.spec.model.inverse_iterations,
        "plant_substeps": robot.spec.model.plant_substeps,
        "gravity": robot.gravity.tolist(),
        "state_layout": model.layout.as_dict(),
        "noise_layout": {"w_l": [0, n], "w_m": [n, 2 * n], "w_theta": [2 * n, 2 * n + p]},
        "actuators": {
            "Ks": robot.Ks.tolist(),
            "Mm": robot.Mm.tolist(),
            "Fm": robot.Fm.tolist(),
            # JSON has no inf: a joint without a limit is null
            "u_max": [float(v) if math.isfinite(v) else None for v in robot.u_max],
        },
        "camera": {
            "K": cam.K.tolist(),
            "R_cw": cam.R_cw.tolist(),
            "position": cam.position.tolist(),
            "width": cam.width,
            "height": cam.height,
            "period": cam.period,
            "delay": cam.delay,
        },
        "camera_depends_on_theta": model.camera_depends_on_theta,
        "functions": fns,
        "content_hash": key,
        "hash_inputs": hash_inputs,
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }


# --------------------------------------------------------------------------- libraries
def load_library(
    robot: str | os.PathLike[str] | RobotSpec = "paper_2link", **generate_kwargs: Any
) -> ModelLibrary:
    """Generate (or reuse from the cache) and load the library of ``robot``
    (``generate_kwargs`` as :func:`generate`)."""
    return ModelLibrary(generate(robot, **generate_kwargs).out_dir)


def library_for(
    sc: Scenario, out: str | os.PathLike[str] | None = None, robot: RobotSpec | None = None
) -> ModelLibrary:
    """Generate (or reuse) and load the library a scenario runs on.

    The scenario's ``integrator`` (when set and different from the robot's) gives a library
    of its own, ``<robot>_<integrator>``.  The camera timing and the filter's buffer are
    checked against the robot spec first (:func:`~amsfe_sym.scenario.camera_timing`), so a
    bad scenario fails before anything is generated.  ``robot`` replaces the spec of
    ``sc.robot`` (a derived spec, e.g. a sweep's other true payload; give it its own name).

    Raises:
        ConfigError: the scenario's camera timing does not fit the robot or the filter.
    """
    from amsfe_sym.estimation.registry import estimator_class
    from amsfe_sym.preflight import check_scenario_shapes

    spec = robot if robot is not None else load_spec(sc.robot)
    check_scenario_shapes(sc, spec)  # every wrong-length vector, before generating
    camera_timing(
        sc,
        spec.camera.period,
        spec.camera.delay,
        needs_history=estimator_class(sc.estimator).needs_history,
    )
    if sc.integrator and sc.integrator != spec.model.integrator:
        spec = replace(
            spec,
            name=f"{spec.name}_{sc.integrator}",
            model=replace(spec.model, integrator=sc.integrator),  # type: ignore[arg-type]
        )
    return load_library(spec, out=out)
