"""Section 1 of ``amsfe bench``: cold and cached generation, each in a fresh process."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from amsfe_sym.apps.bench.timing import round4
from amsfe_sym.errors import CodegenError, describe

__all__ = ["bench_generation"]


_GEN_SCRIPT = """
import json, resource, sys, time
t0 = time.perf_counter()
from amsfe_sym.codegen import generate
t1 = time.perf_counter()
r = generate(sys.argv[1], out=sys.argv[2], force=sys.argv[3] == "1", progress=sys.argv[4] == "1")
who = (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
peak = max(resource.getrusage(w).ru_maxrss for w in who)
print(json.dumps({"import_s": t1 - t0, "seconds": r.seconds, "reused": r.reused,
                  "timings": r.timings, "out_dir": str(r.out_dir), "peak_mb": peak / 1024}))
"""


def _generate_in_subprocess(
    robot: str, out: Path, force: bool, progress: bool = False
) -> dict[str, Any]:
    """``generate`` in a fresh Python process: its result, wall time and peak memory
    (``peak_mb``: the largest resident set of the process or of a compiler it ran [MB]).
    With ``progress``, generate's stage and compile-progress lines go to this stderr."""
    t0 = time.perf_counter()
    flags = ["1" if force else "0", "1" if progress else "0"]
    proc = subprocess.run(
        [sys.executable, "-c", _GEN_SCRIPT, robot, str(out), *flags],
        stdout=subprocess.PIPE,
        stderr=None if progress else subprocess.PIPE,
        text=True,
    )
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise CodegenError(
            describe(
                f"generate({robot!r})",
                "success",
                (proc.stderr or "its messages above").strip()[-2000:],
                "see above",
            )
        )
    res: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    res["process_wall_s"] = wall
    return {k: (round4(v) if isinstance(v, float) else v) for k, v in res.items()}


def bench_generation(robot: str) -> dict[str, Any]:
    """Cold (``force=True``) and cached ``generate`` of ``robot`` into a temporary folder.

    Each call runs in a fresh Python process, as ``amsfe generate`` does, so "cached"
    includes nothing the first call left in memory.  ``seconds`` is the time inside
    :func:`~amsfe_sym.codegen.generate`, ``process_wall_s`` adds interpreter start-up and
    imports.
    """
    with tempfile.TemporaryDirectory(prefix="amsfe-bench-gen-") as tmp:
        cold = _generate_in_subprocess(robot, Path(tmp), force=True)
        cached = _generate_in_subprocess(robot, Path(tmp), force=False)
        src = Path(cold["out_dir"])
        lines = (src / f"{src.name}.c").read_text().count("\n") if src.is_dir() else 0
    cold["timings"] = {k: round4(v) for k, v in cold["timings"].items()}
    return {"cold": cold, "cached": cached, "c_lines": lines}
