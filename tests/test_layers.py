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
    "amsfe_sym.runtime.compiled_estimator",
    "amsfe_sym.runtime.compiled_loop",
    "amsfe_sym.estimation",
    "amsfe_sym.sim",
    "amsfe_sym.sim.builders",
    "amsfe_sym.sim.loop",
    "amsfe_sym.sim.compiled",
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


#: What each stage may import from the package (docs/architecture.md, "Layers").  Keys and
#: values are module paths below ``amsfe_sym``; a key covers the module or package of that
#: name, and the longest key wins.  Imports inside functions count too.
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "_toml": {"errors"},
    "camera_frame": set(),
    "provenance": {""},
    "spec": {"_toml", "errors"},
    "scenario": {"_toml", "errors", "spec"},
    "load": {"errors", "spec", "load"},
    "symbolic": {"errors", "spec", "load", "symbolic"},
    "codegen": {"", "errors", "spec", "scenario", "load", "symbolic", "runtime", "estimation"},
    "runtime": {"errors", "runtime"},
    # the compiled estimators implement estimation's Estimator interface over the library
    "runtime.compiled_estimator": {"errors", "runtime", "estimation", "camera_frame"},
    "estimation": {"errors", "camera_frame", "estimation"},
    "sim.sensors": {"errors", "camera_frame", "spec"},
    "sim.trajectory": {"errors"},
    "control": {"errors", "runtime", "sim.trajectory", "control"},
    "sim": {
        "errors",
        "camera_frame",
        "scenario",
        "runtime",
        "estimation",
        "control",
        "provenance",
        "plots",
        "sim",
    },
    # apps: the sweep package runs simulations (codegen for its libraries), never the CLI,
    # study or bench
    "sweep": {
        "errors",
        "_toml",
        "spec",
        "scenario",
        "preflight",
        "codegen",
        "control",
        "estimation",
        "sim",
        "provenance",
        "runtime",
        "sweep",
    },
}


def _stage(module: str) -> str | None:
    keys = [k for k in ALLOWED if module == k or module.startswith(k + ".")]
    return max(keys, key=len) if keys else None


def _allowed(target: str, allowed: set[str]) -> bool:
    return any(a == "" or target == a or target.startswith(a + ".") for a in allowed)


def test_each_stage_imports_only_earlier_ones() -> None:
    import ast
    from pathlib import Path

    import amsfe_sym

    root = Path(amsfe_sym.__file__).parent
    bad = []
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        module = ".".join(p for p in parts if p != "__init__")
        stage = _stage(module)
        if stage is None:  # the apps (cli, check, bench, study, plots, ...) may import all
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = (
                [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else []
            )
            for name in names:
                if name == "amsfe_sym":
                    target = ""
                elif name.startswith("amsfe_sym."):
                    target = name[len("amsfe_sym.") :]
                else:
                    continue
                if not _allowed(target, ALLOWED[stage] | {stage}):
                    bad.append(f"{module} imports amsfe_sym.{target}")
    assert bad == [], "\n".join(bad)
