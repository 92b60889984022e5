"""Load a generated model library and call its functions through a thin ctypes binding.

Calling a CasADi ``Function`` from Python costs ~6-20 us per call (argument conversion),
more than the 2-link model's whole evaluation.  :class:`CompiledFunction` instead calls the
generated C entry point ``int f(const double** arg, double** res, long long* iw,
double* w, int mem)`` directly with argument and work buffers allocated once, so a call
costs about a microsecond (``amsfe bench`` measures it).  Inputs are copied into the
preallocated buffers; outputs are returned as numpy views of the output buffers
(column-major, overwritten by the next call) or as copies.

The runtime never needs Pinocchio or symbols: it reads ``manifest.json`` and the library.
Anyone can also load a function with plain CasADi: :meth:`ModelLibrary.external`.
"""

from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import os
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import CodegenError, ShapeError, describe
from amsfe_sym.runtime.manifest import FunctionSignature, Manifest, read_manifest

__all__ = ["CompiledFunction", "ModelLibrary", "file_sha256"]

_c_int_p = ctypes.POINTER(ctypes.c_longlong)
_c_double_p = ctypes.POINTER(ctypes.c_double)


class CompiledFunction:
    """One generated function with preallocated buffers.

    Args:
        lib: The loaded shared library.
        name: Function name (as in the manifest).
        signature: The manifest's signature of the function.
    """

    def __init__(self, lib: ctypes.CDLL, name: str, signature: FunctionSignature) -> None:
        self.name = name
        try:
            # a private function pointer (lib[name], not the CDLL's shared attribute), called
            # with prebuilt ctypes arguments and no argtypes conversion (see call_into)
            self._f = lib[name]
            work = lib[f"{name}_work"]
        except AttributeError as exc:
            raise CodegenError(
                describe(
                    f"function {name!r}",
                    "a symbol in the library",
                    "none",
                    "regenerate it: amsfe generate <robot> --force",
                )
            ) from exc
        self._f.restype = ctypes.c_int
        sz = [ctypes.c_longlong(0) for _ in range(4)]
        work.restype = ctypes.c_int
        work(*[ctypes.byref(s) for s in sz])
        sz_arg, sz_res, sz_iw, sz_w = (int(s.value) for s in sz)
        self.input_names = [i.name for i in signature.inputs]
        self.output_names = [o.name for o in signature.outputs]
        self.input_shapes = [i.shape for i in signature.inputs]
        self.output_shapes = [o.shape for o in signature.outputs]
        self._in = [np.zeros(i.np_shape, order="F") for i in signature.inputs]
        self._out = [np.zeros(o.np_shape, order="F") for o in signature.outputs]
        self._iw = np.zeros(max(sz_iw, 1), dtype=np.int64)
        self._w = np.zeros(max(sz_w, 1))
        self._arg = (ctypes.c_void_p * max(sz_arg, 1))()
        self._res = (ctypes.c_void_p * max(sz_res, 1))()
        for i, a in enumerate(self._in):
            self._arg[i] = a.ctypes.data if a.size else None
        for i, r in enumerate(self._out):
            self._res[i] = r.ctypes.data if r.size else None
        # Prebuilt ctypes objects: with no argtypes, ctypes passes them as they are, which
        # saves the per-call int -> pointer conversion (~0.1 us of the ~0.4 us ctypes call).
        self._call_args = (
            ctypes.c_void_p(ctypes.addressof(self._arg)),
            ctypes.c_void_p(ctypes.addressof(self._res)),
            ctypes.c_void_p(self._iw.ctypes.data),
            ctypes.c_void_p(self._w.ctypes.data),
            ctypes.c_int(0),
        )
        self._n_in = len(self._in)
        # One assignment target per input, so call_into is a single `t[...] = a` loop:
        # the buffer itself for vectors, a reshaping wrapper for matrices, a sink for
        # empty inputs (e.g. theta when p = 0, whose argument is ignored).
        self._targets: list[Any] = [
            _Sink() if b.size == 0 else (b if b.ndim == 1 else _MatrixInput(b)) for b in self._in
        ]

    def call_into(self, *args: Any) -> list[NDArray[np.float64]]:
        """Evaluate; return the internal output buffers (valid until the next call)."""
        if len(args) != self._n_in:
            raise ShapeError(
                describe(
                    f"{self.name}()",
                    f"{self._n_in} inputs {self.input_names}",
                    f"{len(args)}",
                    "pass every input",
                )
            )
        try:
            for target, a in zip(self._targets, args, strict=False):  # lengths checked
                target[...] = a
        except ValueError as exc:
            raise self._shape_error(args) from exc
        if self._f(*self._call_args) != 0:
            raise CodegenError(f"{self.name}() returned an error code")
        return self._out

    def _shape_error(self, args: tuple[Any, ...]) -> ShapeError:
        """The error for the first argument that does not fit its buffer."""
        bad_buf, bad_arg = self._in[0], args[0]
        for target, buf, a in zip(self._targets, self._in, args, strict=True):
            try:
                _scratch(target, buf)[...] = a
            except ValueError:
                bad_buf, bad_arg = buf, a
                break
        return ShapeError(
            describe(
                f"{self.name}() input",
                f"shape {bad_buf.shape}",
                f"shape {np.shape(bad_arg)}",
                "reshape the argument",
            )
        )

    def __call__(self, *args: Any) -> tuple[NDArray[np.float64], ...]:
        """Evaluate and return copies of all outputs."""
        return tuple(o.copy() for o in self.call_into(*args))


class _Sink:
    """Assignment target of an empty input: accepts and ignores its argument."""

    def __setitem__(self, key: Any, value: Any) -> None:
        pass


class _MatrixInput:
    """Assignment target of a matrix input: reshapes the argument into the buffer."""

    def __init__(self, buf: NDArray[np.float64]) -> None:
        self.buf = buf

    def __setitem__(self, key: Any, value: Any) -> None:
        self.buf[...] = np.reshape(value, self.buf.shape)


def _scratch(target: Any, buf: NDArray[np.float64]) -> Any:
    """An assignment target like ``target`` over a scratch copy of ``buf``."""
    if isinstance(target, _MatrixInput):
        return _MatrixInput(np.empty_like(buf))
    return target if isinstance(target, _Sink) else np.empty_like(buf)


def file_sha256(path: Path) -> str:
    """sha256 hex digest of a file's bytes (the library's own hash in the manifest)."""
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _verify_library(path: Path, expected: object) -> None:
    """Refuse (one line, never a segfault) a library whose bytes are not those generated."""
    try:
        found = file_sha256(path)
    except OSError as exc:
        found = f"an unreadable file ({exc.strerror})"
    if not isinstance(expected, str):
        found = "a manifest without library_sha256 (made by an older toolkit)"
    if found != expected:
        raise CodegenError(
            describe(
                str(path),
                "the library whose sha256 the manifest records",
                found if " " in found else f"sha256 {found[:12]}... (damaged or replaced)",
                f"rebuild it: amsfe generate --force (into {path.parent.parent})",
            )
        )


class ModelLibrary:
    """A generated robot library: its manifest plus lazily bound functions.

    Args:
        path: ``generated/<name>/`` or its ``manifest.json``.
        robot_files: The URDF and ``robot.toml`` (None for a bare URDF) of the robot the
            caller loaded, in place of the paths the manifest recorded when it was built.

    Attributes:
        name, n, p, N, T: The manifest's robot name, joints n, parameters p, state size
            N = 4n + p and sampling interval T [s].
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        robot_files: tuple[str | os.PathLike[str], str | os.PathLike[str] | None] | None = None,
    ) -> None:
        p = Path(path)
        mpath = p / "manifest.json" if p.is_dir() else p
        self.manifest: Manifest = read_manifest(mpath)
        if robot_files is not None:
            # the URDF and robot.toml of the robot this run loaded: a library reused from the
            # content-keyed cache names those of the checkout that built it, which another
            # checkout sharing the cache may have deleted (/tf, the marker's pose read them)
            urdf, spec = robot_files
            self.manifest = dataclasses.replace(
                self.manifest, urdf=str(urdf), spec=None if spec is None else str(spec)
            )
        m = self.manifest
        self.name, self.n, self.p, self.N, self.T = m.name, m.n, m.p, m.N, m.T
        self.dir = mpath.parent
        self.library_path = self.dir / self.manifest.library
        _verify_library(self.library_path, self.manifest.raw.get("library_sha256"))
        try:
            self._lib = ctypes.CDLL(str(self.library_path))
        except OSError as exc:
            raise CodegenError(
                describe(
                    str(self.library_path),
                    "a loadable library",
                    str(exc),
                    "regenerate it: amsfe generate <robot> --force",
                )
            ) from exc
        self._fns: dict[str, CompiledFunction] = {}

    def function(self, name: str) -> CompiledFunction:
        """The compiled function ``name`` (bound once, then reused)."""
        if name not in self._fns:
            sigs = self.manifest.functions
            if name not in sigs:
                raise CodegenError(
                    describe(
                        f"function {name!r}",
                        f"one of {sorted(sigs)}",
                        "unknown name",
                        "use a name listed in manifest.json (or regenerate with a newer toolkit)",
                    )
                )
            self._fns[name] = CompiledFunction(self._lib, name, sigs[name])
        return self._fns[name]

    def external(self, name: str) -> Any:
        """The function as a ``casadi.external`` (the plain-CasADi way to use the library)."""
        import casadi as ca

        return ca.external(name, str(self.library_path))

    @cached_property
    def layout(self) -> dict[str, slice]:
        """State blocks q, qd, qm, qmd, theta as slices of x (eq. 2)."""
        return {k: slice(a, b) for k, (a, b) in self.manifest.state_layout.items()}

    @cached_property
    def _stiffness_theta(self) -> list[tuple[int, int]]:
        joints = self.manifest.joints
        return [
            (i, joints.index(t.target))
            for i, t in enumerate(self.manifest.theta)
            if t.kind == "joint_stiffness"
        ]

    def stiffness(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Ks [N m/rad] per joint with the joint-stiffness parameters set to ``theta``
        (the runtime twin of ``Robot.stiffness_at``, read from the manifest)."""
        Ks = np.array(self.manifest.actuators.Ks, dtype=float)
        for i, j in self._stiffness_theta:
            Ks[j] = theta[i]
        return Ks

    @property
    def stiffness_theta_index(self) -> NDArray[np.int32]:
        """Per joint, the index of the theta entry holding its stiffness, or -1 (the table
        :meth:`stiffness` reads; the C controllers take it as ``ks_theta``)."""
        index = np.full(self.n, -1, dtype=np.int32)
        for i, j in self._stiffness_theta:
            index[j] = i
        return index

    @property
    def theta_true(self) -> NDArray[np.float64]:
        return np.array([t.true for t in self.manifest.theta], dtype=float)

    @property
    def theta_initial(self) -> NDArray[np.float64]:
        return np.array([t.initial for t in self.manifest.theta], dtype=float)
