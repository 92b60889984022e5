"""ctypes mirrors of the C runtime's structs, read from the headers themselves.

The parameter blocks, diagnostics and records of ``c/amsfe_runtime.h`` and ``c/amsfe_loop.h``
are declared once, in C.  :func:`header_fields` turns a ``typedef struct { ... } NAME;`` of
those headers into a ctypes ``_fields_`` list, so the Python side cannot drift from the C
side when a field is added (a hand-copied list that missed one would shift every later
field silently).  The headers are ours and use a small subset of C: scalar ``int``,
``long``, ``long long``, ``double``, ``size_t``, ``unsigned char``, pointers to any of them
(passed as ``void *``), fixed arrays (``double z[2]``), several names per declaration and
comments.
Anything else is refused with :class:`~amsfe_sym.errors.ConfigError` when the module that
uses it is imported (a test imports them all).
"""

from __future__ import annotations

import ctypes
import re
from functools import cache
from pathlib import Path
from typing import Any

from amsfe_sym.errors import ConfigError, describe

__all__ = ["C_DIR", "c_struct", "header_fields"]

#: The C runtime's sources and headers (compiled into every full library).
C_DIR = Path(__file__).resolve().parent / "c"

_SCALARS: dict[str, Any] = {
    "int": ctypes.c_int,
    "long": ctypes.c_long,
    "long long": ctypes.c_longlong,
    "double": ctypes.c_double,
    "size_t": ctypes.c_size_t,
    "unsigned char": ctypes.c_ubyte,
}
_STRUCT = re.compile(r"typedef\s+struct\s*\{(?P<body>[^{}]*)\}\s*(?P<name>\w+)\s*;")
_DECLARATOR = re.compile(r"^(?P<stars>\**)\s*(?P<name>\w+)\s*(?:\[(?P<count>\d+)\])?$")


@cache
def _structs(header: str) -> dict[str, str]:
    text = (C_DIR / header).read_text()
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    text = re.sub(r"//[^\n]*", " ", text)
    return {m["name"]: m["body"] for m in _STRUCT.finditer(text)}


def header_fields(header: str, struct: str) -> list[tuple[str, Any]]:
    """The ctypes ``_fields_`` of ``typedef struct { ... } struct;`` in ``c/<header>``.

    Args:
        header: File name in :data:`C_DIR`, e.g. ``"amsfe_loop.h"``.
        struct: The typedef's name, e.g. ``"amsfe_ctrl_params"``.

    Raises:
        ConfigError: the struct is missing or uses a declaration this reader does not know.
    """
    body = _structs(header).get(struct)
    if body is None:
        raise ConfigError(
            describe(f"{header}", f"a 'typedef struct {{...}} {struct};'", "none", "fix the header")
        )
    fields: list[tuple[str, Any]] = []
    for decl in (d.strip() for d in body.split(";")):
        if not decl:
            continue
        m = re.match(
            r"^(?:const\s+)?(unsigned char|long long|int|long|double|size_t)\b(.*)$", decl, re.S
        )
        if m is None:
            raise ConfigError(
                describe(f"{header}: {struct}", "a scalar type the reader knows", decl, "extend it")
            )
        base = _SCALARS[m[1]]
        for part in m[2].split(","):
            d = _DECLARATOR.match(part.strip())
            if d is None:
                raise ConfigError(
                    describe(f"{header}: {struct}", "a declarator", part.strip(), "extend it")
                )
            ctype: Any = ctypes.c_void_p if d["stars"] else base
            if d["count"]:
                ctype = ctype * int(d["count"])
            fields.append((d["name"], ctype))
    return fields


def c_struct(name: str, header: str, struct: str) -> type[ctypes.Structure]:
    """A ctypes Structure class ``name`` with the fields of ``struct`` in ``c/<header>``
    (:func:`header_fields`)."""
    doc = f"``{struct}`` of ``{header}`` (its fields read from the header)."
    return type(
        name, (ctypes.Structure,), {"_fields_": header_fields(header, struct), "__doc__": doc}
    )
