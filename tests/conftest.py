"""Shared fixtures: every robot is generated (and compiled) at most once per session.

Libraries go to the content-hash cache of :func:`amsfe_sym.codegen.default_out_dir`:
``$AMSFE_GENERATED_DIR``, set here to the repository's ``generated/`` when it is not set (the
default is the current directory's, and tests change it), so a second test run, and the
README's main command, reuse them instead of compiling again.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

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
    ) -> tuple[Robot, ModelLibrary]:
        key = f"{robot}|{sorted((lock or {}).items())}|{parts}"
        if key not in self._cache:
            res = generate(robot, lock=lock, parts=parts)
            self._cache[key] = (load_robot(robot, lock=lock), ModelLibrary(res.out_dir))
        return self._cache[key]


@pytest.fixture(scope="session")
def libraries() -> _Libraries:
    """Session-wide access to generated libraries: ``libraries.get(name) -> (robot, lib)``."""
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


@pytest.fixture(scope="module")
def paper_sim() -> tuple[Scenario, ModelLibrary]:
    """paper-sim and its library (compiled once per session: the content-hash cache); a
    module that records its own runs defines its own ``paper_sim``."""
    sc = load_scenario("paper-sim")
    return sc, library_for(sc)
