"""Shared fixtures: every robot is generated (and compiled) at most once per session.

Libraries go to the content-hash cache of :func:`amsfe_sym.codegen.default_out_dir`:
``$AMSFE_GENERATED_DIR``, set here to the repository's ``generated/`` when it is not set (the
default is the current directory's, and tests change it), so a second test run, and the
README's main command, reuse them instead of compiling again.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

from amsfe_sym.codegen import ALL_PARTS, compiler, generate, library_for
from amsfe_sym.load import Robot, load_robot
from amsfe_sym.load.spec import robots_dir
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.scenario import Scenario, load_scenario

# one library cache for the session, whatever folder a test runs in (monkeypatch.chdir)
os.environ.setdefault(
    "AMSFE_GENERATED_DIR", str(Path(__file__).resolve().parent.parent / "generated")
)

# In CI (CI=true) property tests draw a fixed sequence of examples, so a red run can be
# reproduced; locally they explore new examples each run.
settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

SHIPPED = sorted(d.name for d in robots_dir().iterdir() if (d / "robot.toml").is_file())
#: The shipped robots the suite compiles.  The Panda's library (7 joints, rk4 model) takes
#: ~30 s of compile on two shared cores, too much for the suite's budget: its spec and model
#: are checked without compiling (tests/test_panda.py, and test_dynamics.py over SHIPPED).
COMPILED = [name for name in SHIPPED if name != "panda"]
DATA = Path(__file__).parent / "data"
EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@functools.cache
def c_program_built(scenario: str = "paper-sim", program: str = "amsfe_node") -> Path:
    """The C ``program`` (``amsfe_node`` or ``amsfe_arm``) of ``scenario``'s library, built
    (once per content, :func:`amsfe_sym.ros.cnode_build.build_node`) before a test starts it
    beside a peer: the first build takes tens of seconds on a loaded 2-core machine, and a
    peer's start timeout (``amsfe play --start-timeout 60``) must not pay it (a cold cache
    once failed that way at load 6)."""
    from amsfe_sym.ros.cnode_build import build_node

    return build_node(library_for(load_scenario(scenario)), program=program).path


def ur5_three_thetas(folder: Path) -> Path:
    """``robot.toml`` in ``folder``: example-robot-data's UR5 with one parameter of each kind
    (a 2 kg payload at tool0, the forearm's mass, the elbow's stiffness)."""
    urdf = erd_urdf("ur_description/urdf/ur5_robot.urdf")
    path = folder / "robot.toml"
    path.write_text(
        f'urdf = "{urdf}"\n'
        "[[theta]]\nname = 'payload'\nkind = 'payload_mass'\ntarget = 'tool0'\n"
        "offset = [0.0, 0.0, 0.1]\ntrue = 2.0\ninitial = 0.0\n"
        "[[theta]]\nname = 'forearm'\nkind = 'link_mass'\ntarget = 'forearm_link'\n"
        "true = 2.275\ninitial = 2.0\n"
        "[[theta]]\nname = 'k3'\nkind = 'joint_stiffness'\ntarget = 'elbow_joint'\n"
        "true = 500.0\ninitial = 400.0\n"
    )
    return path


def build_example(name: str, lib: ModelLibrary, out: Path) -> Path:
    """Compile ``examples/<name>.c`` against a generated library as a user would (its
    header and shared library only, no Python at run time; warnings are errors)."""
    subprocess.run(
        [
            compiler(),
            "-O1",
            "-Wall",
            "-Werror",
            str(EXAMPLES / f"{name}.c"),
            f"-I{lib.dir}",
            f"-L{lib.dir}",
            f"-l{lib.manifest.library[3:-3]}",
            f"-Wl,-rpath,{lib.dir}",
            "-lm",
            "-o",
            str(out),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return out


def erd_urdf(rel: str) -> Path:
    """Path of a URDF shipped by the example-robot-data package (a real third-party file)."""
    from importlib import metadata

    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    base = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    path = base / rel
    if not path.is_file():
        pytest.skip(f"{rel} not in this example-robot-data version")
    return path


class _Libraries:
    def __init__(self) -> None:
        self._cache: dict[str, tuple[Robot, ModelLibrary]] = {}

    def get(
        self,
        robot: str | Path,
        lock: dict[str, float] | None = None,
        parts: tuple[str, ...] = ALL_PARTS,
        cflags: tuple[str, ...] = (),
    ) -> tuple[Robot, ModelLibrary]:
        key = f"{robot}|{sorted((lock or {}).items())}|{parts}|{cflags}"
        if key not in self._cache:
            res = generate(robot, lock=lock, parts=parts, extra_cflags=cflags or None)
            self._cache[key] = (load_robot(robot, lock=lock), ModelLibrary(res.out_dir))
        return self._cache[key]


@pytest.fixture(scope="session")
def libraries() -> _Libraries:
    """Session-wide access to generated libraries: ``libraries.get(name) -> (robot, lib)``
    (``cflags``: extra compiler flags, e.g. ``("-O0",)`` for a library only checked, never
    timed, that no other test compiles)."""
    return _Libraries()


@pytest.fixture(scope="session")
def one_chord_2link(tmp_path_factory: pytest.TempPathFactory) -> ModelLibrary:
    """paper_2link with one chord step in its inverse transition (``inverse_iterations = 1``:
    residuals ~1e-6..1e-4, an inverse that does not converge), compiled once per session at
    -O0 for the tests of a non-converged inverse (test_compiled_estimator.py,
    test_compiled_backward_map.py)."""
    import shutil

    folder = tmp_path_factory.mktemp("inv1") / "paper_2link_inv1"
    folder.mkdir()
    src = robots_dir() / "paper_2link"
    shutil.copy(src / "paper_2link.urdf", folder)
    spec = (src / "robot.toml").read_text()
    spec = spec.replace('name = "paper_2link"', 'name = "paper_2link_inv1"')
    spec = spec.replace("inverse_iterations = 6 ", "inverse_iterations = 1 ")
    assert "inverse_iterations = 1 " in spec
    (folder / "robot.toml").write_text(spec)
    gen = generate(folder / "robot.toml", extra_cflags=["-O0"], out=folder.parent / "gen")
    return ModelLibrary(gen.out_dir)


@pytest.fixture(scope="session")
def paper_1link_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """paper_1link compiled once per session (per xdist worker) into a folder of its own:
    ``paper_1link/`` and the compiled objects' cache ``.objects/``.  The tests of the cache
    copy it (:func:`copy_build`) and damage their copy: a rebuild of the copy then compiles
    nothing again but links (the object cache), as a user's rebuild does."""
    out = tmp_path_factory.mktemp("paper_1link_build")
    generate("paper_1link", out=out)
    return out


def copy_build(build: Path, dest: Path, objects_only: bool = False) -> Path:
    """A copy of :func:`paper_1link_build`'s folder in ``dest`` (only ``.objects/`` if
    ``objects_only``); ``dest``."""
    import shutil

    dest.mkdir(parents=True, exist_ok=True)
    for item in build.iterdir():
        if item.is_dir() and (not objects_only or item.name == ".objects"):
            shutil.copytree(item, dest / item.name)
    return dest


@pytest.fixture(scope="module")
def paper_sim() -> tuple[Scenario, ModelLibrary]:
    """paper-sim and its library (compiled once per session: the content-hash cache); a
    module that records its own runs defines its own ``paper_sim``."""
    sc = load_scenario("paper-sim")
    return sc, library_for(sc)


# ------------------------------------------------------------------ tiers (docs/how-to/tests.md)
def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--nightly",
        action="store_true",
        help="also run the tests marked nightly (repeats of a scenario CI runs once, docs "
        "blocks whose commands a named test runs): docs/how-to/tests.md",
    )


#: The suite's longest tests (CPU and wall seconds of a whole run, docs/how-to/tests.md), the
#: costliest first: started first, one after the other on alternate workers, so that none of
#: them is the run's tail (at the end of the collection order they kept one worker busy for
#: minutes after the other had finished).  None uses a module-scoped fixture: moved out of its
#: module, it sets nothing up twice.
HEAVY_FIRST = (
    "tests/test_docs_blocks.py::test_the_page_s_blocks_run[docs/tutorials/real-recording.md]",
    "tests/test_docs_blocks.py::test_the_page_s_blocks_run[docs/calibrate.md]",
    "tests/test_docs_blocks.py::test_the_page_s_blocks_run[docs/tutorials/your-arm.md]",
    "tests/test_bench.py::test_bench_prints_every_row_and_the_routes_agree",
    "tests/test_real_images.py::test_hand_eye_residuals_on_real_frames",
)


def heavy_first(items: list[pytest.Item], workers: int) -> list[pytest.Item]:
    """``items`` with the :data:`HEAVY_FIRST` tests moved to the front of the first chunk
    each of ``workers`` xdist workers is sent (``--dist load``, the default: it sends each
    worker a run of consecutive tests, a quarter of its share), the costliest first and
    alternating between the workers; the others keep their order."""
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    heavy = sorted((it for it in items if it.nodeid in rank), key=lambda it: rank[it.nodeid])
    rest = [it for it in items if it.nodeid not in rank]
    if workers <= 1:
        return heavy + rest
    chunk = max(len(items) // workers // 4, 2)  # xdist's LoadScheduling.schedule
    out = list(rest)
    for w in range(workers):  # worker w's first chunk starts at w * chunk
        out[w * chunk : w * chunk] = heavy[w::workers]
    return out


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The :data:`HEAVY_FIRST` tests first (:func:`heavy_first`); without ``--nightly``, a
    test marked ``nightly`` is skipped with the mark's reason."""
    items[:] = heavy_first(items, int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))
    if config.getoption("--nightly"):
        return
    for item in items:
        mark = item.get_closest_marker("nightly")
        if mark is not None:
            why = mark.args[0] if mark.args else "a repeat of a behaviour CI runs once"
            item.add_marker(pytest.mark.skip(reason=f"nightly (--nightly runs it): {why}"))


#: With this environment variable set to a file, each test's cost is appended to it as a JSON
#: line: CPU seconds of the test's process and of the children it waited for (DDS nodes,
#: compilers, docs blocks), and wall seconds.  CPU time is the cost on a shared, loaded
#: machine, where wall time is not; tools/test_costs.py sums it by file (docs/how-to/tests.md).
COSTS_ENV = "AMSFE_TEST_COSTS"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    out = os.environ.get(COSTS_ENV)
    t0, w0 = os.times(), time.monotonic()
    yield
    if not out:
        return
    t1, w1 = os.times(), time.monotonic()
    row = {
        "test": item.nodeid,
        "cpu": round(t1.user - t0.user + t1.system - t0.system, 3),
        "cpu_children": round(
            t1.children_user - t0.children_user + t1.children_system - t0.children_system, 3
        ),
        "wall": round(w1 - w0, 3),
        "worker": os.environ.get("PYTEST_XDIST_WORKER", "main"),
    }
    with open(out, "a") as f:
        f.write(json.dumps(row) + "\n")


# ------------------------------------------------------------- shared lockstep runs over DDS
#: Seconds of sample time of the shared lockstep runs (1001 ticks of paper-sim, 30 camera
#: frames; 2 s before): their assertions, every topic equal to ``amsfe simulate`` tick for
#: tick, hold for 1 s as for 10 s (docs/how-to/tests.md).
LOCKSTEP_S = 1.0


@dataclass(frozen=True)
class LockstepRun:
    """One ``amsfe sim-node --lockstep`` + ``amsfe node --controller amsfe --record`` run over
    real DDS (both exited 0): the record's topics, each process's output, the record."""

    topics: dict[str, list[Any]]
    node_text: str
    arm_text: str
    record: Path


class _LockstepRuns:
    """The runs, made once per test session in a folder every xdist worker of the session
    sees: the first test to ask makes a run while holding its lock (``fcntl.flock``), the
    others wait for it and read its record."""

    def __init__(self, folder: Path) -> None:
        self._folder = folder
        self._read: dict[str, LockstepRun] = {}

    def get(
        self, scenario: str, node: str, arm: str | None = None, duration: float = LOCKSTEP_S
    ) -> LockstepRun:
        """The run of ``amsfe node SCENARIO --impl NODE`` and ``amsfe sim-node SCENARIO
        --lockstep [--impl ARM]`` (None: the arm's default) for ``duration`` s.  A run that
        failed fails every test that asks for it and is not made again."""
        import fcntl

        name = f"{scenario}-{node}-{arm or 'default'}-{duration:g}"
        if name in self._read:
            return self._read[name]
        folder = self._folder / name
        done = folder / "done.json"
        with open(self._folder / f"{name}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
            if not done.exists():
                folder.mkdir(exist_ok=True)
                try:
                    texts = self._make(folder, scenario, node, arm, duration)
                except Exception as err:
                    done.write_text(json.dumps({"error": f"{type(err).__name__}: {err}"}))
                    raise
                done.write_text(json.dumps({"node": texts[0], "arm": texts[1]}))
        made = json.loads(done.read_text())
        if "error" in made:
            pytest.fail(f"the shared lockstep run {name} failed: {made['error']}")
        from tests.test_node_record import _bag

        rec = folder / "rec"
        self._read[name] = LockstepRun(_bag(rec), made["node"], made["arm"], rec)
        return self._read[name]

    @staticmethod
    def _make(
        folder: Path, scenario: str, node: str, arm: str | None, duration: float
    ) -> tuple[str, str]:
        """Run the two processes (a skip, the [ros] extra missing, is raised as it is)."""
        from tests.test_ros import PATIENT_ARM, PATIENT_NODE, _finish, _ros_env, _start

        env = _ros_env(folder)
        d = f"{duration:g}"
        arm_args = ["--impl", arm] if arm else []
        procs = []
        try:
            procs.append(_start(env, "node", scenario, "--controller", "amsfe", "--impl", node,
                                "--duration", d, "--record", str(folder / "rec"),
                                *PATIENT_NODE))  # fmt: skip
            procs.append(_start(env, "sim-node", scenario, "--lockstep", "--duration", d,
                                *arm_args, *PATIENT_ARM))  # fmt: skip
        finally:
            results = _finish(procs, 180.0)
        for code, text in results:
            assert code == 0, text
        return results[0][1], results[1][1]


@pytest.fixture(scope="session")
def lockstep_runs(tmp_path_factory: pytest.TempPathFactory) -> _LockstepRuns:
    """Lockstep runs over DDS shared by the tests that assert on them (tests/test_ros.py,
    test_cnode.py, test_carm.py): ``lockstep_runs.get(scenario, node_impl, arm_impl,
    duration)``, each made once per session, whichever xdist worker asks first (the
    workers' base folders share the session's parent; ``-n 0``: a folder of its own)."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        folder = tmp_path_factory.getbasetemp().parent / "lockstep-runs"
        folder.mkdir(exist_ok=True)
    else:
        folder = tmp_path_factory.mktemp("lockstep-runs")
    return _LockstepRuns(folder)
