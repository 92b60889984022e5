"""Building a library: symbols -> C source + header -> shared library -> manifest, moved
into ``generated/<name>/`` only when it compiled and loaded.

Output is written to a temporary folder and moved into place only when the library has
compiled and loaded, so bad input, a failed build or Ctrl-C leaves ``generated/`` as it was.
The manifest records the library's own sha256: the cache reuses, and the runtime loads, only
a library whose bytes still match it (a truncated or damaged ``.so`` is rebuilt here and
refused by :class:`~amsfe_sym.runtime.library.ModelLibrary`).  Hidden temporary folders left
by a killed run (its pid gone, or older than an hour) are removed by the next build.

Compiler flags: ``-O1`` by default (see docs/explanation/codegen.md for the measurements behind it);
override with ``$AMSFE_CFLAGS`` or ``--cflags``.  ``-march=native`` ties the library to
the CPU; it is allowed, and since the flags are hashed, a changed flag rebuilds.
"""

from __future__ import annotations

import ctypes
import functools
import json
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from amsfe_sym.codegen.cache import (
    ALL_PARTS,
    MANIFEST,
    build_lock,
    cached_dir,
    cflags,
    check_parts,
    clean_stale_tmp,
    compiler,
    content_hash,
    default_out_dir,
    manifest_of,
    replace_dir,
)
from amsfe_sym.codegen.compile_units import (
    GENERATED_PREFIX,
    OBJECT_CACHE,
    RUNTIME_C,
    Unit,
    build_jobs,
    compile_library,
    runtime_unit,
)
from amsfe_sym.codegen.compile_units import say as _say
from amsfe_sym.codegen.manifest import manifest_document
from amsfe_sym.codegen.preflight import check_model_bounds
from amsfe_sym.core.folders import TMP_MARKER, make_tmp
from amsfe_sym.core.interrupts import DeferredSignals, checkpoint
from amsfe_sym.core.jsonfile import to_json
from amsfe_sym.errors import CodegenError, RunFolderError, describe
from amsfe_sym.load.spec import RobotSpec, load_spec
from amsfe_sym.runtime.library import file_sha256
from amsfe_sym.runtime.stability import JointMode, StiffJoint, modes_from_manifest, stiff_joints

__all__ = ["GenerateResult", "cached_library", "generate", "lowered_stiffness"]

#: The hand-written C glue of the compiled estimators, built into every library.


@dataclass(frozen=True)
class GenerateResult:
    """What :func:`generate` did.

    Attributes:
        out_dir: ``generated/<name>/``.
        manifest_path: Its ``manifest.json``.
        library_path: The shared library.
        reused: True when the cache matched and nothing was rebuilt.
        seconds: Wall time of the call [s].
        timings: Per-stage wall times [s] (load, modes, symbolic, codegen, compile) when built.
        modes: Each joint's elastic mode over the workspace (the manifest's ``joint_modes``;
            empty for a library built before they were stored): :meth:`stiff` lists the
            joints the library's model cannot integrate.
    """

    out_dir: Path
    manifest_path: Path
    library_path: Path
    reused: bool
    seconds: float
    timings: dict[str, float]
    modes: tuple[JointMode, ...] = ()

    def stiff(self) -> tuple[StiffJoint, ...]:
        """The joints whose elastic mode the library's model cannot integrate at its T
        (:func:`~amsfe_sym.runtime.stability.stiff_joints`), from the manifest."""
        raw = json.loads(self.manifest_path.read_text())
        return stiff_joints(
            self.modes, float(raw["T"]), str(raw["integrator"]), int(raw["model_substeps"])
        )


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
    parts = check_parts(parts)
    key, _ = content_hash(spec, cflags(extra_cflags), parts)
    parent = Path(out) if out is not None else default_out_dir()
    out_dir = parent / (spec.name if parts == ALL_PARTS else f"{spec.name}-{'-'.join(parts)}")
    lib = cached_dir(out_dir, key)
    if lib is None:
        return None
    return _reused(out_dir, lib, t_start)


def _reused(out_dir: Path, lib: Path, t_start: float) -> GenerateResult:
    """The result of a cache hit, with the joint modes its manifest stores."""
    try:
        modes = modes_from_manifest(json.loads((out_dir / MANIFEST).read_text())) or ()
    except (OSError, ValueError):
        modes = ()
    return GenerateResult(
        out_dir, out_dir / MANIFEST, lib, True, time.perf_counter() - t_start, {}, modes
    )


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
        progress: Print stage timings to stderr, and one warning line per joint whose
            elastic mode the model cannot integrate (before compiling; a cache hit's
            result has them too: :meth:`GenerateResult.stiff`).
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
    check_model_bounds(spec)  # before any lock file or folder (docs/input-rules.md)
    flags = cflags(extra_cflags)
    parts = check_parts(parts)
    key, hash_inputs = content_hash(spec, flags, parts)
    parent = Path(out) if out is not None else default_out_dir()
    out_dir = parent / (spec.name if parts == ALL_PARTS else f"{spec.name}-{'-'.join(parts)}")
    _check_library_folder(out_dir)
    build_jobs()  # a bad $AMSFE_BUILD_JOBS is refused before any work, not ignored
    if not force:
        lib = cached_dir(out_dir, key)
        if lib is not None:
            return _reused(out_dir, lib, t_start)

    # one build per library at a time, across processes (pytest-xdist workers, study
    # workers, two shells): the others wait and then find it in the cache
    with build_lock(parent / f".{out_dir.name}.lock"):
        if not force:
            lib = cached_dir(out_dir, key)
            if lib is not None:
                return _reused(out_dir, lib, t_start)
        return _build(
            spec, parts, flags, key, hash_inputs, parent, out_dir, progress, t_start, force
        )


def _signals_held(fn: Callable[..., GenerateResult]) -> Callable[..., GenerateResult]:
    """``fn`` run with Ctrl-C and SIGTERM held (:class:`DeferredSignals`)."""

    @functools.wraps(fn)
    def held(*args: Any, **kwargs: Any) -> GenerateResult:
        with DeferredSignals():
            return fn(*args, **kwargs)

    return held


@_signals_held
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
    force: bool = False,
) -> GenerateResult:
    """Load, build the symbols, generate C, compile and move into ``out_dir`` (see
    :func:`generate`).

    Ctrl-C and SIGTERM are held while it runs (:class:`~amsfe_sym.core.interrupts.
    DeferredSignals`) and raised at its checkpoints between stages, in the symbolic build and
    while the compiler runs: raised inside the yourdfpy/trimesh imports or CasADi they used
    to be swallowed (the build went on to the end).  The temporary folder is removed."""
    # heavy imports only when building
    from amsfe_sym.codegen.modes import joint_modes, modes_document, robot_source, warn_stiff
    from amsfe_sym.load import load_robot
    from amsfe_sym.symbolic.model import build_functions

    timings: dict[str, float] = {}
    t = time.perf_counter()
    robot_obj = load_robot(spec)
    timings["load"] = time.perf_counter() - t
    t = time.perf_counter()
    modes = joint_modes(robot_obj)
    timings["modes"] = time.perf_counter() - t
    _say(  # once the input is known good: bad input is one line, this is not an error
        progress,
        f"[amsfe] {spec.name}: {'rebuilding' if force else 'no library in the cache'} "
        f"({out_dir}): generating it (model, C, compile: once per robot and settings, "
        "then it is reused)",
    )
    other = _other_source(out_dir, spec)
    _say(
        progress and other is not None,
        f"[amsfe] {spec.name}: {out_dir} held the library of another robot of that name "
        f"({other}); it is replaced, and the two will take turns there (give one its own "
        "`name` in a robot.toml, or another --out, to keep both)",
    )
    if progress:  # before the compile, not after it (a 7-DOF arm compiles for ~20 s)
        m = spec.model
        warn_stiff(
            stiff_joints(modes, m.T, m.integrator, m.model_substeps), robot_source(spec), modes
        )
    if progress:
        for line in lowered_stiffness(
            spec, robot_obj.Ks.tolist(), [j.name for j in robot_obj.joints]
        ):
            _say(True, line)
    checkpoint()
    t = time.perf_counter()
    model = build_functions(robot_obj, parts)
    timings["symbolic"] = time.perf_counter() - t
    checkpoint()
    _say(progress, f"[amsfe] {spec.name}: symbolic model built in {timings['symbolic']:.2f} s")

    parent.mkdir(parents=True, exist_ok=True)
    clean_stale_tmp(parent, spec.name)
    tmp = make_tmp(parent, f".{spec.name}-{os.getpid()}-")
    tmp.chmod(0o755)
    try:
        t = time.perf_counter()
        cname = f"{spec.name}.c"
        import casadi as ca  # here, not at import: a cache hit (amsfe estimate) needs none

        # one prefix for every robot: the same model under another name is the same C, and
        # its object comes from the object cache (codegen/compile_units.py)
        gen = ca.CodeGenerator(
            cname, {"with_header": True, "with_mem": False, "prefix": GENERATED_PREFIX}
        )
        for f in model.internal.values():  # first: the contract's MX graphs call them
            gen.add(f)
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
            checkpoint()
        cwd = os.getcwd()
        try:
            os.chdir(tmp)
            gen.generate()
        finally:
            os.chdir(cwd)
        checkpoint()
        timings["codegen"] = time.perf_counter() - t
        t = time.perf_counter()
        libname = f"lib{spec.name}.so"
        # every unit is cached by its content and the headers it can include (those of
        # runtime/c and of tmp), so a model another library has (a sweep's derived spec, the
        # same arm under another name) links its objects; the largest unit starts first
        units = [Unit(cname, shared=True, local=True, label="generated")]
        (tmp / "amsfe_model_config.h").write_text(model_config_header(model))
        if model.chained:  # the contract functions written in C over the generated stage
            units.append(runtime_unit("amsfe_model.c", local=True))
        if "estimator" in parts:  # the C glue calls the est_* functions
            shutil.copy(RUNTIME_C / "amsfe_runtime.h", tmp)
            units += [
                runtime_unit(name, local=True)
                for name in (
                    "amsfe_runtime.c",
                    "amsfe_est_tick.c",
                    "amsfe_est_late.c",
                    "amsfe_est_run.c",
                )
            ]
        if set(parts) == set(ALL_PARTS):  # the loop calls the laws, the plant, the estimators
            shutil.copy(RUNTIME_C / "amsfe_loop.h", tmp)
            units += [
                runtime_unit(name) for name in ("amsfe_loop.c", "amsfe_ctrl.c", "amsfe_blend.c")
            ]
            shutil.copy(RUNTIME_C / "amsfe_watchdog.h", tmp)  # a live node's watchdogs
            units.append(runtime_unit("amsfe_watchdog.c"))
        if "estimator" in parts:  # the dense kernels of the estimators and the loop (O3 pragma)
            units.append(runtime_unit("amsfe_kernels.c"))
        # --force rebuilds the shared objects too (and refreshes them in the cache)
        proc = compile_library(
            units,
            compiler(),
            flags,
            tmp,
            libname,
            {k: hash_inputs.get(k) for k in ("compiler", "cflags", "machine", "cpu")},
            parent / OBJECT_CACHE,
            progress,
            spec.name,
            reuse=not force,
        )
        checkpoint()  # a Ctrl-C in the terminal stops the compiler too: say that, not its exit
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
        manifest = manifest_document(model, key, hash_inputs, libname, cname, timings)
        manifest["library_sha256"] = file_sha256(tmp / libname)
        manifest["joint_modes"] = modes_document(robot_obj, modes)
        (tmp / MANIFEST).write_text(to_json(manifest))
        checkpoint()
        (tmp / TMP_MARKER).unlink()  # what is renamed into place is the library folder
        replace_dir(tmp, out_dir)
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
        modes,
    )


def lowered_stiffness(spec: RobotSpec, Ks: Sequence[float], joints: Sequence[str]) -> list[str]:
    """One line per joint whose default stiffness a spec without ``[actuators] Ks`` (a bare
    URDF) got lowered from :data:`~amsfe_sym.load.parameters.DEFAULT_KS`, saying why and how
    to set it; empty when the spec gives Ks.  The default keeps each joint's
    link-against-motor mode at w T <= 0.5 (a light wrist at T = 1 ms would make the
    discrete model diverge; :func:`~amsfe_sym.load.parameters.default_stiffness`)."""
    if spec.actuators.Ks is not None:
        return []
    default = 1000.0  # load.parameters.DEFAULT_KS (not imported: it imports Pinocchio)
    return [
        f"[amsfe] {spec.name}: joint {name}: default stiffness Ks lowered from {default:g} to "
        f"{k:.4g} N m/rad, so that its link-against-motor mode keeps w T <= 0.5 at "
        f"T = {spec.model.T:g} s (w^2 = Ks (1/J + 1/Mm), J its lightest inertia); set your "
        "arm's own with [actuators] Ks in a robot.toml (docs/reference/robot-spec.md)"
        for name, k in zip(joints, Ks, strict=True)
        if float(k) < default * (1 - 1e-9)
    ]


def _other_source(out_dir: Path, spec: RobotSpec) -> str | None:
    """The source (robot.toml or URDF) of the library in ``out_dir`` if it is not ``spec``'s:
    the folder is named by the robot's name, so a bare ``panda.urdf`` and the shipped
    ``robots/panda`` share ``generated/panda`` and each build replaces the other's."""
    old = manifest_of(out_dir)
    if old is None:
        return None
    mine = {"urdf": str(spec.urdf), "spec": None if spec.spec_path is None else str(spec.spec_path)}
    theirs = {k: old.get(k) for k in mine}
    if theirs == mine or theirs["urdf"] is None:
        return None
    return str(theirs["spec"] or theirs["urdf"])


def _check_library_folder(out_dir: Path) -> None:
    """A library folder is new, empty or one this tool generated (it holds its manifest): a
    file or a folder of the user's there is never replaced.  A library whose
    manifest was lost (its ``lib*.so`` is there) is rebuilt."""
    if not out_dir.exists() or (out_dir / MANIFEST).is_file():
        return
    if out_dir.is_dir() and any(out_dir.glob("lib*.so")):
        return
    if out_dir.is_dir() and not any(out_dir.iterdir()):
        return
    raise RunFolderError(
        describe(
            f"library folder {out_dir}",
            f"a new folder or a library amsfe generated (it holds {MANIFEST})",
            "a folder of other files" if out_dir.is_dir() else "a file",
            "choose another --out (the parent of generated libraries); amsfe never replaces "
            "what it did not write",
        )
    )


def model_config_header(model: Any) -> str:
    """``amsfe_model_config.h``: the constants the hand-written C of ``runtime/c`` needs from
    the model (n, p, T [s], the rk4 model's steps per T, the motor inertias Mm [kg m^2]) and
    whether the library has the chained rk4 step (``AMSFE_MODEL_CHAIN``)."""
    robot = model.robot
    mm = ", ".join(repr(float(v)) for v in robot.Mm)
    return (
        "/* written by amsfe_sym.codegen for this library: do not edit */\n"
        "#ifndef AMSFE_MODEL_CONFIG_H\n#define AMSFE_MODEL_CONFIG_H\n"
        f"#define AMSFE_MODEL_N {robot.n}\n"
        f"#define AMSFE_MODEL_P {robot.p}\n"
        f"#define AMSFE_MODEL_T {float(robot.spec.model.T)!r}\n"
        f"#define AMSFE_MODEL_SUBSTEPS {int(robot.spec.model.model_substeps)}\n"
        f"#define AMSFE_MODEL_MM {{{mm}}}\n"
        f"#define AMSFE_MODEL_CHAIN {1 if model.chained else 0}\n"
        "#endif\n"
    )
