"""The generated library is embeddable: a plain C program links it without Python and prints
the same numbers as the Python path."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.codegen import compiler


def test_c_program_matches_python(libraries, tmp_path: Path) -> None:
    if shutil.which(compiler()) is None:
        pytest.skip("no C compiler")
    _, lib = libraries.get("paper_2link")
    m = lib.manifest.raw
    exe = tmp_path / "embed"
    src = Path(__file__).parent / "c" / "embed_transition.c"
    # link against the already-built shared library: nothing is compiled twice
    subprocess.run(
        [
            compiler(),
            "-O1",
            f'-DAMSFE_HEADER="{lib.dir / m["header"]}"',
            str(src),
            f"-L{lib.dir}",
            f"-l{m['library'][3:-3]}",
            f"-Wl,-rpath,{lib.dir}",
            "-o",
            str(exe),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    rng = np.random.default_rng(4)
    x = np.concatenate([rng.uniform(-1, 1, 8), [0.15]])
    u = rng.uniform(-2, 2, 2)
    out = subprocess.run(
        [str(exe), *[repr(float(v)) for v in np.concatenate([x, u])]],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    got = {
        line.split()[0]: np.array([float(v) for v in line.split()[1:]]) for line in out.splitlines()
    }
    xn, A, G = lib.function("transition_step")(x, u)
    y = lib.function("camera")(x[:2], x[8:])[0]
    # C prints column-major buffers; the Python views are column-major too
    np.testing.assert_array_equal(got["x_next"], xn)
    np.testing.assert_array_equal(got["A"], A.ravel(order="F"))
    np.testing.assert_array_equal(got["Gamma"], G.ravel(order="F"))
    np.testing.assert_array_equal(got["y"], y)
