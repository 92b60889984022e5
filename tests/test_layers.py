"""The pipeline's layers: the runtime side never needs CasADi or Pinocchio."""

from __future__ import annotations

import subprocess
import sys

#: Everything a simulation run needs once its library exists.
RUNTIME_SIDE = (
    "amsfe_sym.runtime",
    "amsfe_sym.runtime.library",
    "amsfe_sym.runtime.manifest",
    "amsfe_sym.runtime.models",
    "amsfe_sym.estimation",
    "amsfe_sym.sim",
    "amsfe_sym.sim.builders",
    "amsfe_sym.sim.loop",
    "amsfe_sym.sim.record",
    "amsfe_sym.control",
    "amsfe_sym.scenario",
    "amsfe_sym.provenance",
    "amsfe_sym.plots",
    "amsfe_sym.simulate",
)


def test_runtime_side_imports_neither_casadi_nor_pinocchio() -> None:
    code = (
        "import importlib, sys\n"
        f"for m in {RUNTIME_SIDE!r}:\n"
        "    importlib.import_module(m)\n"
        "heavy = sorted(m for m in ('casadi', 'pinocchio') if m in sys.modules)\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert out == "", f"imported by the runtime side: {out}"


def test_the_check_can_fail() -> None:
    """The same probe sees CasADi once the code generator is imported."""
    code = "import sys, amsfe_sym.codegen; print('casadi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"
