"""The ctypes mirrors of the C runtime's structs, read from the headers, have the C
compiler's layout: every field's offset and every struct's size as ``offsetof`` / ``sizeof``
print them."""

from __future__ import annotations

import ctypes
import subprocess

import pytest

from amsfe_sym.codegen import compiler
from amsfe_sym.errors import ConfigError
from amsfe_sym.runtime import compiled_estimator, loop_abi
from amsfe_sym.runtime.cheader import C_DIR, header_fields

MIRRORS = [
    (compiled_estimator._Params, "amsfe_runtime.h", "amsfe_params"),
    (compiled_estimator.RuntimeDiagnostics, "amsfe_runtime.h", "amsfe_diag"),
    (compiled_estimator._Dims, "amsfe_runtime.h", "amsfe_dims"),
    (loop_abi.CtrlParams, "amsfe_loop.h", "amsfe_ctrl_params"),
    (loop_abi.CtrlOut, "amsfe_loop.h", "amsfe_ctrl_out"),
    (loop_abi.SimParams, "amsfe_loop.h", "amsfe_sim_params"),
    (loop_abi.SimRecords, "amsfe_loop.h", "amsfe_sim_records"),
    (loop_abi.SimulationState, "amsfe_loop.h", "amsfe_sim_state"),
]


def test_mirrors_have_the_c_layout(tmp_path) -> None:
    lines = [
        "#include <stddef.h>",
        "#include <stdio.h>",
        '#include "amsfe_loop.h"',
        "int main(void) {",
    ]
    for cls, _, struct in MIRRORS:
        lines.append(f'  printf("{struct} %zu\\n", sizeof({struct}));')
        for name, _ in cls._fields_:
            lines.append(f'  printf("{struct}.{name} %zu\\n", offsetof({struct}, {name}));')
    lines += ["  return 0;", "}"]
    src = tmp_path / "layout.c"
    src.write_text("\n".join(lines) + "\n")
    exe = tmp_path / "layout"
    subprocess.run([compiler(), "-I", str(C_DIR), "-o", str(exe), str(src)], check=True)
    c = dict(
        line.split()
        for line in subprocess.run(
            [str(exe)], capture_output=True, text=True, check=True
        ).stdout.splitlines()
    )
    py = {}
    for cls, _, struct in MIRRORS:
        py[struct] = str(ctypes.sizeof(cls))
        for name, _ in cls._fields_:
            py[f"{struct}.{name}"] = str(getattr(cls, name).offset)
    assert py == {k: c[k] for k in py}


def test_unknown_declarations_are_refused(tmp_path) -> None:
    h = tmp_path / "x.h"
    h.write_text("typedef struct {\n  float f; /* not a type the reader knows */\n} bad_t;\n")
    with pytest.raises(ConfigError, match="float f"):
        header_fields(str(h), "bad_t")
    with pytest.raises(ConfigError, match="missing_t"):
        header_fields(str(h), "missing_t")
