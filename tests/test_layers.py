"""The pipeline's layers (docs/explanation/architecture.md): each room imports only the rooms
before it,
no module imports itself back through others, and the runtime side never needs CasADi or
Pinocchio."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import amsfe_sym

#: Everything a simulation run needs once its library exists.
RUNTIME_SIDE = (
    "amsfe_sym.runtime",
    "amsfe_sym.runtime.library",
    "amsfe_sym.runtime.manifest",
    "amsfe_sym.runtime.models",
    "amsfe_sym.runtime.compiled_estimator",
    "amsfe_sym.runtime.compiled_loop",
    "amsfe_sym.estimation",
    "amsfe_sym.signals",
    "amsfe_sym.sim",
    "amsfe_sym.sim.builders",
    "amsfe_sym.sim.loop",
    "amsfe_sym.sim.compiled",
    "amsfe_sym.sim.record",
    "amsfe_sym.control",
    "amsfe_sym.scenario",
    "amsfe_sym.load.spec",
    "amsfe_sym.core.provenance",
    "amsfe_sym.apps.plots.run",
    "amsfe_sym.apps.simulate",
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
    """The same probe sees CasADi once the symbolic model is imported (the code generator
    imports it only to build: a cache hit needs neither CasADi nor Pinocchio)."""
    code = "import sys, amsfe_sym.symbolic.model; print('casadi' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"


#: What each room may import from the package (docs/explanation/architecture.md, "Rooms").  Keys and
#: values are module paths below ``amsfe_sym``; a key covers the module or package of that
#: name, and the longest key wins; a room may always import itself.  Imports inside
#: functions count too.  ``from amsfe_sym import __version__`` (the package root) is allowed
#: everywhere, nothing else of the root.
ALLOWED: dict[str, set[str]] = {
    "errors": set(),
    "arrays": set(),  # the array types: every room may import them (EVERYONE below)
    "core": {"errors"},
    "load": {"errors", "core"},
    "scenario": {"errors", "core", "load.spec"},
    "signals": {"errors", "core", "load.spec"},
    "symbolic": {"errors", "core", "load"},
    # codegen loads what it built (runtime) and checks a scenario's camera timing against the
    # estimator's history (estimation.registry) and its vectors' lengths (signals) first
    "codegen": {
        "errors",
        "core",
        "load",
        "scenario",
        "signals",
        "symbolic",
        "runtime",
        "estimation.registry",
    },
    "runtime": {"errors"},
    # what a topic means, for logs and live nodes alike (and the marker its images show)
    "topics": {"errors", "core", "vision.spec"},
    # the camera chain: images, CameraInfo, the marker, undistortion (docs/camera.md)
    "vision": {"errors", "core"},
    # the compiled estimators implement estimation's Estimator interface over the library
    "runtime.compiled_estimator": {
        "errors",
        "runtime",
        "estimation",
        "core.camera_frame",
        "core.values",
    },
    "runtime.compiled_loop": {"errors", "runtime", "estimation", "core.camera_frame"},
    # the compiled estimators' parameters for a log's effort, read off estimation's models
    "runtime.effort_params": {"errors", "runtime", "estimation"},
    # core.values: the named settings shared with the scenario (BACKWARD_MAPS)
    "estimation": {"errors", "core.camera_frame", "core.values"},
    "control": {"errors", "runtime", "signals.trajectory"},
    "sim": {
        "errors",
        "core",
        "load.spec",
        "scenario",
        "signals",
        "runtime",
        "estimation",
        "control",
    },
    # robot logs sit beside the loop: they read a run's result, build its estimator and draw
    # /tf with the robot's kinematics (Pinocchio, only when writing a bag)
    "logs": {
        "errors",
        "core",
        "load",
        "scenario",
        "runtime",
        "estimation",
        "sim",
        "topics",
        "vision",
    },
    # the live ROS 2 nodes: the applications' peers (rclpy imported only inside ros/)
    "ros": {
        "errors",
        "core",
        "load",
        "scenario",
        "signals",
        "codegen",
        "runtime",
        "estimation",
        "control",
        "sim",
        "logs",
        "topics",
        "vision",
    },
    # the camera calibration: a log read as estimate reads it, the robot's model and camera
    "calibration": {"errors", "core", "load", "logs"},
    # the applications may import every room, never the command line
    "apps": {
        "errors",
        "core",
        "load",
        "scenario",
        "signals",
        "symbolic",
        "codegen",
        "runtime",
        "estimation",
        "control",
        "sim",
        "logs",
        "topics",
        "ros",
        "vision",
        "calibration",
    },
    "apps.cli": {""},  # the command line: everything
    # the public API composes the applications' parts (never the command line)
    "api": {
        "errors",
        "core",
        "load",
        "scenario",
        "signals",
        "codegen",
        "runtime",
        "estimation",
        "control",
        "sim",
        "logs",
        "topics",
        "ros",
        "apps",
    },
    "__main__": {"apps.cli"},
}

#: What every room may import besides its ALLOWED rooms: the array types (amsfe_sym.arrays).
EVERYONE = {"arrays"}

ROOT = Path(amsfe_sym.__file__).parent


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        out[".".join(p for p in parts if p != "__init__")] = path
    return out


def _stage(module: str) -> str | None:
    keys = [k for k in ALLOWED if module == k or module.startswith(k + ".")]
    return max(keys, key=len) if keys else None


def _allowed(target: str, allowed: set[str]) -> bool:
    return any(a == "" or target == a or target.startswith(a + ".") for a in allowed)


def _imports(module: str, path: Path) -> list[tuple[str, list[str]]]:
    """(target module below amsfe_sym, names imported from it) for each import of a module;
    the target ``""`` is the package root."""
    found = []
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            name = node.module or ""
            if node.level:  # relative: resolve against the package
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                name = ".".join([*(p for p in base if p), *([name] if name else [])])
                name = f"amsfe_sym.{name}" if name else "amsfe_sym"
            names = [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name == "amsfe_sym" or a.name.startswith("amsfe_sym."):
                    found.append((a.name[len("amsfe_sym.") :] if "." in a.name else "", []))
            continue
        else:
            continue
        if name == "amsfe_sym":
            found.append(("", names))
        elif name.startswith("amsfe_sym."):
            found.append((name[len("amsfe_sym.") :], names))
    return found


def test_each_room_imports_only_earlier_ones() -> None:
    bad = []
    modules = _modules()
    for module, path in modules.items():
        if module == "":
            continue
        stage = _stage(module)
        assert stage is not None, f"amsfe_sym.{module} is in no room of ALLOWED"
        for target, names in _imports(module, path):
            if target == "":
                extra = sorted(set(names) - {"__version__", "AmsfeError"})
                if extra and "" not in ALLOWED[stage]:
                    bad.append(f"{module} imports {extra} from the package root")
                continue
            if not _allowed(target, ALLOWED[stage] | {stage} | EVERYONE) or (
                _allowed(target, {"apps.cli"}) and module not in ("__main__", "apps.cli")
            ):
                bad.append(f"{module} imports amsfe_sym.{target}")
    assert bad == [], "\n".join(bad)


def test_no_import_cycles() -> None:
    """No module reaches itself through the package's imports (top-level or inside
    functions): a cycle means two modules are one concept, or one belongs elsewhere."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        edges = set()
        for target, names in _imports(module, path):
            # ``from pkg import sub`` imports the submodule pkg.sub
            for t in [target, *(f"{target}.{n}" if target else n for n in names)]:
                if t in modules and t != module:
                    edges.add(t)
        graph[module] = edges
    # a package's __init__ re-exporting its own modules is not a cycle of concepts
    for module in graph:
        graph[module] = {t for t in graph[module] if not module.startswith(t + ".") or t == ""}
    graph.pop("", None)
    for edges in graph.values():
        edges.discard("")
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert cycles == [], f"import cycles: {cycles}"


def test_the_layer_checks_can_fail(tmp_path: Path) -> None:
    """The parser sees an import inside a function and a relative import."""
    src = tmp_path / "m.py"
    src.write_text("def f():\n    from amsfe_sym.apps.cli import main\nfrom ..sim import loop\n")
    found = _imports("estimation.m", src)
    assert ("apps.cli", ["main"]) in found and ("sim", ["loop"]) in found
    assert not _allowed("apps.cli", ALLOWED["estimation"])


def test_no_module_over_500_lines() -> None:
    long = {m: n for m, p in _modules().items() if (n := len(p.read_text().splitlines())) > 500}
    assert long == {}, f"modules over 500 lines: {long}"


def test_each_room_says_what_it_is_for() -> None:
    """Every folder's __init__ has a docstring naming what it may import."""
    missing = []
    for init in ROOT.rglob("__init__.py"):
        doc = ast.get_docstring(ast.parse(init.read_text())) or ""
        if init.parent != ROOT and "may import" not in doc.lower():
            missing.append(str(init.relative_to(ROOT)))
    assert missing == [], f"rooms whose __init__ does not say what they may import: {missing}"
