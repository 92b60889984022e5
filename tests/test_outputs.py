"""The output-path rule (issue 25, items 1 and 2): one function, every command.

:func:`amsfe_sym.core.outputs.check_output` is tested on its own first; then a table holds
one case per output option of the command line, and a test walks the argparse tree of
:func:`amsfe_sym.apps.cli.get_argument_parser` so that a new output option without a case
fails.  Each case is run through ``amsfe_sym.apps.cli.main`` (cheap runs: 0.05 s of
simulated time, no figures) against every rule: a folder of the user's untouched with and
without ``--force``, a file where a folder goes (and a folder where a file goes), an input
of the same command, a parent that cannot be written, and the tool's own output replaced
only with ``--force``.  The last part is the run folder and its bag as one unit under
Ctrl-C and SIGTERM, and every JSON the tool writes read by a strict parser.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from amsfe_sym.apps.cli import get_argument_parser, main
from amsfe_sym.core.folders import MARKER, FolderJob, write_folders
from amsfe_sym.core.jsonfile import NON_FINITE, to_json, write_json
from amsfe_sym.core.outputs import (
    OWN_KEY,
    check_output,
    interrupted_note,
    ledger,
    note_written,
)
from amsfe_sym.errors import RunFolderError

#: A path under a folder nobody can create anything in (procfs), root included.
UNWRITABLE = Path("/proc/amsfe-no-such/out")

SIM = ["simulate", "--controller", "amsfe", "--duration", "0.05", "--no-progress", "--no-plots"]


def _tree(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` with its bytes (None for a folder): a snapshot."""
    return {
        str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def _strict(text: str) -> object:
    """``json.loads`` that refuses NaN, Infinity and -Infinity (RFC 8259)."""

    def bad(name: str) -> object:
        raise ValueError(f"non-standard JSON constant {name}")

    return json.loads(text, parse_constant=bad)


def _one_line(capsys: pytest.CaptureFixture[str], *words: str) -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    assert "Fix: ." not in lines[0] and not lines[0].rstrip().endswith("Fix:"), lines[0]
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


# ---------------------------------------------------------------------------- the function
def test_a_new_path_is_accepted_and_resolved(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    out = check_output(tmp_path / "a" / ".." / "new" / "run", option="--out")
    assert out.resolved == tmp_path.resolve() / "new" / "run"
    assert not out.existed
    assert not (tmp_path / "new").exists()  # nothing is made by the check
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]  # its probe is gone


@pytest.mark.parametrize("force", [False, True])
def test_a_file_is_never_replaced_by_a_folder(tmp_path: Path, force: bool) -> None:
    f = tmp_path / "notes.txt"
    f.write_text("mine")
    with pytest.raises(RunFolderError, match="an existing file"):
        check_output(f, option="--out", force=force)
    assert f.read_text() == "mine"


@pytest.mark.parametrize("force", [False, True])
def test_a_folder_is_never_replaced_by_a_file(tmp_path: Path, force: bool) -> None:
    (tmp_path / "d").mkdir()
    with pytest.raises(RunFolderError, match="an existing folder"):
        check_output(tmp_path / "d", option="--json", kind="file", force=force)


@pytest.mark.parametrize("kind", ["folder", "resume"])
@pytest.mark.parametrize("force", [False, True])
def test_a_folder_of_the_users_is_never_replaced(tmp_path: Path, kind, force: bool) -> None:
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "thesis.tex").write_text("months of work")
    with pytest.raises(RunFolderError, match="did not write"):
        check_output(mine, option="--out", kind=kind, force=force)


def test_the_tools_own_folder_only_with_force(tmp_path: Path) -> None:
    run = tmp_path / "run"
    run.mkdir()
    (run / MARKER).write_text("")
    with pytest.raises(RunFolderError, match="pass --force"):
        check_output(run, option="--out")
    assert check_output(run, option="--out", force=True).existed
    assert check_output(run, option="--out", kind="resume").existed  # a sweep resumes


def test_the_tools_own_file_only_with_force_and_another_file_never(tmp_path: Path) -> None:
    own = write_json(tmp_path / "bench.json", {"a": 1}, own="amsfe bench")
    assert json.loads(own.read_text())[OWN_KEY] == "amsfe bench"
    with pytest.raises(RunFolderError, match="pass --force"):
        check_output(own, option="--json", kind="file")
    check_output(own, option="--json", kind="file", force=True)
    other = tmp_path / "data.json"
    other.write_text('{"results": [1, 2]}')
    with pytest.raises(RunFolderError, match="did not write"):
        check_output(other, option="--json", kind="file", force=True)


@pytest.mark.parametrize(
    ("where", "relation"),
    [("log", "is"), ("log/sub", "is inside"), (".", "holds")],
)
def test_an_input_is_never_written_even_with_force(tmp_path: Path, where, relation) -> None:
    log = tmp_path / "log"
    log.mkdir()
    (log / MARKER).write_text("")  # a bag the tool wrote: --force would trust it
    with pytest.raises(RunFolderError, match=f"it {relation} the input"):
        check_output(tmp_path / where, option="--out", force=True, inputs=[log])


def test_inputs_are_compared_after_resolving_links_and_dots(tmp_path: Path) -> None:
    log = tmp_path / "data" / "log"
    log.mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "data")
    for out in (tmp_path / "link" / "log", tmp_path / "data" / "x" / ".." / "log"):
        with pytest.raises(RunFolderError, match="the input"):
            check_output(out, option="--out", force=True, inputs=[log])


def test_two_outputs_of_one_command_may_not_overlap(tmp_path: Path) -> None:
    run = check_output(tmp_path / "run", option="--out")
    for bag in ("run", "run/bag", "."):
        with pytest.raises(RunFolderError, match="apart from --out"):
            check_output(tmp_path / bag, option="--bag", others=[run])
    check_output(tmp_path / "bag", option="--bag", others=[run])


def test_a_parent_that_is_a_file_or_cannot_be_written(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(RunFolderError, match="is a file"):
        check_output(tmp_path / "f" / "a" / "run", option="--out")
    with pytest.raises(RunFolderError, match="not writable"):
        check_output(UNWRITABLE, option="--out")
    if os.geteuid() != 0:  # root writes into a read-only folder: procfs above covers it
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        try:
            with pytest.raises(RunFolderError, match="not writable"):
                check_output(ro / "run", option="--out")
        finally:
            ro.chmod(0o755)


def test_the_ledger_says_what_was_kept(tmp_path: Path) -> None:
    with ledger() as book:
        run = check_output(tmp_path / "run", option="--out")
        check_output(tmp_path / "bag", option="--bag", others=[run])
        note = interrupted_note(book)
        assert note == (
            f"nothing half-written was kept; not written: --out {tmp_path}/run, "
            f"--bag {tmp_path}/bag"
        )
        note_written([run.resolved])
        assert f"kept, complete: --out {tmp_path}/run; not written: --bag" in interrupted_note(book)
    assert interrupted_note([]) == "nothing half-written was kept"


# ------------------------------------------------------------------ folders as one unit
def test_write_folders_is_both_or_neither(tmp_path: Path) -> None:
    a, b = tmp_path / "a", tmp_path / "b"
    write_folders([FolderJob(a, lambda t: (t / "x").write_text("1"))])
    before = _tree(tmp_path)

    def broken(t: Path) -> None:
        (t / "y").write_text("2")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_folders([FolderJob(a, lambda t: (t / "x").write_text("new")), FolderJob(b, broken)])
    assert _tree(tmp_path) == before  # the old a, whole; no b; no temporary folder

    def appears(t: Path) -> None:  # another writer's b appears before the renames
        b.mkdir()
        (b / "theirs").write_text("3")

    with pytest.raises(RunFolderError, match="another process"):
        write_folders(
            [
                FolderJob(a, lambda t: (t / "x").write_text("new"), replace=True),
                FolderJob(b, appears, replace=False),
            ]
        )
    assert (a / "x").read_text() == "1"  # a put back as it was: both or neither
    assert (b / "theirs").read_text() == "3"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]


# ------------------------------------------------------------------------- strict JSON
def test_json_writer_never_writes_a_bare_nan(tmp_path: Path) -> None:
    import numpy as np

    doc = {"nees_mean": float("nan"), "rmse": np.array([1.0, np.inf]), "n": np.int64(3)}
    text = to_json(doc)
    got = _strict(text)
    assert got == {
        "nees_mean": None,
        "rmse": [1.0, None],
        "n": 3,
        NON_FINITE: {"nees_mean": "nan", "rmse[1]": "inf"},
    }
    with pytest.raises(ValueError, match="NaN"):
        _strict(json.dumps({"x": float("nan")}))  # the parser used here is strict


def test_no_module_writes_json_but_the_one_writer() -> None:
    """Every JSON file goes through amsfe_sym.core.jsonfile (a json.dumps written to a file
    elsewhere could hold a bare NaN again)."""
    src = Path(__file__).resolve().parent.parent / "src" / "amsfe_sym"
    bad = []
    for f in src.rglob("*.py"):
        text = f.read_text()
        if f.name == "jsonfile.py":
            continue
        if "json.dump(" in text or "write_text(json.dumps" in text:
            bad.append(str(f.relative_to(src)))
    assert bad == []


# ------------------------------------------------------------ every command's options
@dataclass(frozen=True)
class Case:
    """One output option of the command line and how to run its command cheaply.

    Attributes:
        argv: ``argv(tmp, path)``: the command writing ``path``.
        kind: ``folder``, ``resume``, ``file`` or ``parent`` (core.outputs.Kind).
        force: The command has ``--force``.
        with_input: ``with_input(tmp)``: a command whose output is one of its inputs, made
            the tool's own output so that only the input rule can refuse it (None: the
            command has no input path).
        child: For a ``parent`` folder, the library folder the command writes in it.
    """

    argv: Callable[[Path, Path], list[str]]
    kind: str
    force: bool
    with_input: Callable[[Path], list[str]] | None
    child: str = "paper_2link"


def _own_run(tmp: Path) -> Path:
    run = tmp / "earlier-run"
    assert main([*SIM, "--out", str(run)]) == 0
    return run


def _sweep_file(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    p = folder / "small.toml"
    p.write_text(
        '[sweep]\nscenario = "paper-sim"\nduration = 0.05\nestimators = ["oosm"]\n'
        'controllers = ["amsfe"]\nseeds = [0]\n[axes]\n"camera.delay" = [0]\n'
    )
    return p


def _sweep_in_own_folder(tmp: Path) -> list[str]:
    sw = tmp / "sw"
    spec = _sweep_file(sw)
    (sw / MARKER).write_text("")
    return ["sweep", str(spec), "--out", str(sw), "--workers", "0", "--no-plots", "--force"]


#: ``amsfe bench`` with every section skipped but the machine's header (the outputs are
#: what these tests judge, not the timings).
SECTIONS = ["generation", "calls", "estimators", "tick", "loop", "scaling", "logs", "vision"]
BENCH = ["bench", "--skip", *SECTIONS]

CASES: dict[tuple[str, str], Case] = {
    ("simulate", "--out"): Case(
        lambda tmp, p: [*SIM, "--out", str(p)],
        "folder",
        True,
        lambda tmp: [
            "simulate",
            str(_own_run(tmp) / "config.toml"),
            "--duration",
            "0.05",
            "--no-plots",
            "--no-progress",
            "--out",
            str(tmp / "earlier-run"),
            "--force",
        ],
    ),
    ("simulate", "--bag"): Case(
        lambda tmp, p: [*SIM, "--out", str(tmp / "the-run"), "--bag", str(p)],
        "folder",
        True,
        lambda tmp: [
            "simulate",
            str(_own_run(tmp) / "config.toml"),
            "--duration",
            "0.05",
            "--no-plots",
            "--no-progress",
            "--out",
            str(tmp / "new-run"),
            "--bag",
            str(tmp / "earlier-run"),
            "--force",
        ],
    ),
    ("estimate", "--out"): Case(
        lambda tmp, p: ["estimate", str(_log(tmp)), "--no-plots", "--out", str(p)],
        "folder",
        True,
        lambda tmp: ["estimate", str(_log(tmp)), "--out", str(_log(tmp)), "--force"],
    ),
    ("calibrate", "--out"): Case(
        lambda tmp, p: [*CALIBRATE, str(_calib_log(tmp)), "--no-plots", "--out", str(p)],
        "folder",
        True,
        lambda tmp: [*CALIBRATE, str(_calib_log(tmp)), "--out", str(_calib_log(tmp)), "--force"],
    ),
    ("study", "--out"): Case(
        lambda tmp, p: [
            "study",
            "--seeds",
            "1",
            "--estimators",
            "oosm",
            "--duration",
            "0.05",
            "--workers",
            "1",
            "--no-progress",
            "--out",
            str(p),
        ],
        "folder",
        True,
        lambda tmp: [
            "study",
            str(_own_run(tmp) / "config.toml"),
            "--seeds",
            "1",
            "--out",
            str(tmp / "earlier-run"),
            "--force",
        ],
    ),
    ("sweep", "--out"): Case(
        lambda tmp, p: [
            "sweep",
            str(_sweep_file(tmp / "spec")),
            "--out",
            str(p),
            "--workers",
            "0",
            "--no-plots",
            "--no-progress",
        ],
        "resume",
        True,
        _sweep_in_own_folder,
    ),
    ("bench", "--json"): Case(
        lambda tmp, p: [*BENCH, "--json", str(p)],
        "file",
        True,
        None,
    ),
    ("generate", "--out"): Case(
        lambda tmp, p: ["generate", "--out", str(p)], "parent", False, None
    ),
    ("check", "--out"): Case(
        lambda tmp, p: ["check", "--samples", "1", "--out", str(p)],
        "parent",
        False,
        None,
        "paper_2link-model",  # check builds the model part only
    ),
    ("bench", "--out"): Case(lambda tmp, p: [*BENCH, "--out", str(p)], "parent", False, None),
    # refused before rclpy is touched; a good path would start a live node (tests/test_ros.py)
    ("node", "--record"): Case(
        lambda tmp, p: ["node", "--record", str(p), "--duration", "0.05"], "folder", False, None
    ),
    ("live", "--record"): Case(  # the node's record, checked before either process starts
        lambda tmp, p: ["live", "--record", str(p), "--duration", "0.05"], "folder", False, None
    ),
}

#: Options that name a path the command reads (not an output).
INPUTS = {
    ("calibrate", "log"),
    ("calibrate", "--log-spec"),
    ("estimate", "log"),
    ("estimate", "--log-spec"),
    ("sweep", "spec"),
    ("play", "log"),
    ("node", "--topic-spec"),
    ("node", "--node-exe"),
    ("live", "--topic-spec"),
    ("sim-node", "--topic-spec"),
    ("sim-node", "--arm-exe"),
    ("play", "--topic-spec"),
    ("camera-node", "--topic-spec"),
}


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = get_argument_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _path_options() -> set[tuple[str, str]]:
    """Every option of every command that names a path: a FILE or DIR metavar, a name
    among out/bag/json/record, or help that speaks of a folder or of writing."""
    found = set()
    for name, sp in _subcommands().items():
        for a in sp._actions:
            text = (a.help or "").lower()
            pathy = (
                a.dest in ("out", "bag", "json", "record", "log", "spec")
                or a.metavar in ("FILE", "DIR")
                or " folder" in text
                or "write" in text
            )
            flag = a.nargs == 0  # --force, --report, --no-plots: no path
            if pathy and not flag and a.dest not in ("robot", "scenario"):
                found.add((name, a.option_strings[-1] if a.option_strings else a.dest))
    return found


def test_every_output_option_has_a_case() -> None:
    assert _path_options() - INPUTS == set(CASES)


def test_every_command_that_replaces_has_force() -> None:
    for (cmd, _), case in CASES.items():
        if case.force:
            assert any(a.dest == "force" for a in _subcommands()[cmd]._actions), cmd


_LOG: dict[str, Path] = {}


def _log(tmp: Path) -> Path:
    """A bag written by ``amsfe simulate --bag`` (one per session, copied into ``tmp``)."""
    if "bag" not in _LOG:
        import tempfile

        root = Path(tempfile.mkdtemp(prefix="amsfe-test-log-"))
        assert main([*SIM, "--out", str(root / "run"), "--bag"]) == 0
        _LOG["bag"] = root / "run" / "bag"
    dest = tmp / "log"
    if not dest.exists():
        shutil.copytree(_LOG["bag"], dest)
    return dest


#: The calibration test arm (tests/data/calibrate): 6 s of calib-sim's motion determine its
#: camera to +-3 mm (docs/calibrate.md, "Long enough").
CALIB = Path(__file__).parent / "data" / "calibrate"
CALIBRATE = ["calibrate", "--robot", str(CALIB / "robot.toml")]


def _calib_log(tmp: Path) -> Path:
    """A 6 s calib-sim bag (one per session, copied into ``tmp``) that ``amsfe calibrate``
    calibrates."""
    if "calib" not in _LOG:
        import tempfile

        root = Path(tempfile.mkdtemp(prefix="amsfe-test-calib-"))
        sim = ["simulate", str(CALIB / "calib-sim.toml"), "--controller", "truth-ct"]
        argv = [*sim, "--duration", "6", "--no-progress", "--no-plots", "--bag"]
        assert main([*argv, "--out", str(root / "run")]) == 0
        _LOG["calib"] = root / "run" / "bag"
    dest = tmp / "calib-log"
    if not dest.exists():
        shutil.copytree(_LOG["calib"], dest)
    return dest


@pytest.fixture()
def tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


OPTIONS = sorted(CASES)
IDS = [f"{c}{o}" for c, o in OPTIONS]


def _id(key: tuple[str, str]) -> str:
    return f"{key[0]}{key[1]}"


@pytest.mark.parametrize("key", OPTIONS, ids=IDS)
@pytest.mark.parametrize("force", [False, True], ids=["", "force"])
def test_a_folder_of_the_users_is_untouched(key, force: bool, tmp: Path, capsys) -> None:
    case = CASES[key]
    if force and not any(a.dest == "force" for a in _subcommands()[key[0]]._actions):
        pytest.skip("the command has no --force")
    mine = tmp / "mine"
    target = mine / case.child if case.kind == "parent" else mine
    target.mkdir(parents=True)
    (target / "thesis.tex").write_text("months of work")
    argv = case.argv(tmp, mine)
    before = _tree(mine)
    code = main([*argv, "--force"] if force else argv)
    assert code == 2
    _one_line(capsys, "did not write" if case.kind != "file" else "an existing folder")
    assert _tree(mine) == before


@pytest.mark.parametrize("key", OPTIONS, ids=IDS)
def test_the_wrong_kind_of_path_is_refused(key, tmp: Path, capsys) -> None:
    case = CASES[key]
    if case.kind == "file":
        (tmp / "d").mkdir()
        wrong, words = tmp / "d", ["an existing folder"]
    else:
        (tmp / "d").write_text("mine")
        wrong, words = tmp / "d", ["an existing file"]
    argv = case.argv(tmp, wrong)
    before = _tree(tmp)
    assert main([*argv, "--force"] if case.force else argv) == 2
    _one_line(capsys, *words)
    assert _tree(tmp) == before


@pytest.mark.parametrize("key", OPTIONS, ids=IDS)
def test_an_unwritable_parent_is_refused_before_any_work(key, tmp: Path, capsys) -> None:
    case = CASES[key]
    (tmp / "f").write_text("x")
    for where, words in ((UNWRITABLE, ["not writable"]), (tmp / "f" / "out", ["is a file"])):
        argv = case.argv(tmp, where)
        before = _tree(tmp)
        assert main(argv) == 2
        _one_line(capsys, *words)
        assert _tree(tmp) == before


@pytest.mark.parametrize("key", [k for k in OPTIONS if CASES[k].with_input], ids=_id)
def test_an_input_of_the_command_is_refused_even_with_force(key, tmp: Path, capsys) -> None:
    argv = CASES[key].with_input(tmp)  # type: ignore[misc]
    before = _tree(tmp)
    assert main(argv) == 2
    _one_line(capsys, "the input", "even with --force")
    assert _tree(tmp) == before


@pytest.mark.parametrize(
    "key", [k for k in OPTIONS if CASES[k].kind in ("folder", "file") and CASES[k].force], ids=_id
)
def test_the_tools_own_output_is_replaced_only_with_force(key, tmp: Path, capsys) -> None:
    case = CASES[key]
    out = tmp / ("report.json" if case.kind == "file" else "out")
    argv = case.argv(tmp, out)
    assert main(argv) == 0
    capsys.readouterr()
    before = _tree(tmp)
    assert main(argv) == 2
    _one_line(capsys, "pass --force")
    assert _tree(tmp) == before
    assert main([*argv, "--force"]) == 0
    assert out.exists()
    assert not [p for p in tmp.iterdir() if ".old-" in p.name or ".tmp-" in p.name]


def test_a_sweep_folder_is_resumed_without_force(tmp: Path, capsys) -> None:
    argv = CASES[("sweep", "--out")].argv(tmp, tmp / "out")
    assert main(argv) == 0
    assert (tmp / "out" / MARKER).is_file()
    capsys.readouterr()
    assert main(argv) == 0
    assert "1 already done" in capsys.readouterr().out


def test_a_library_folder_of_the_users_is_never_replaced(tmp: Path, capsys) -> None:
    """``generate --out DIR`` writes ``DIR/<robot>``: a folder of the user's there is not a
    library (no manifest) and is refused, even with --force (a rebuild)."""
    mine = tmp / "libs" / "paper_2link"
    mine.mkdir(parents=True)
    (mine / "notes.md").write_text("mine")
    assert main(["generate", "--out", str(tmp / "libs"), "--force"]) == 2
    _one_line(capsys, "library folder", "never replaces")
    assert (mine / "notes.md").read_text() == "mine"


# ------------------------------------------------- simulate --bag: one unit under Ctrl-C
@pytest.mark.parametrize("bag", ["inside", "elsewhere"])
@pytest.mark.parametrize("signal_name", ["Ctrl-C", "SIGTERM"])
def test_an_interrupted_simulate_bag_keeps_neither(
    bag: str, signal_name: str, tmp: Path, capsys, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C (or SIGTERM) while the bag is written: no run folder without its bag, no bag
    without its run; the message names what was not written."""
    import amsfe_sym.logs.write
    from amsfe_sym.apps.cli import Terminated

    real = amsfe_sym.logs.write.run_bag_filler

    def interrupted(res, urdf_text=None, images=None):
        fill = real(res, urdf_text, images)

        def go(path: Path) -> None:
            fill(path)
            raise Terminated if signal_name == "SIGTERM" else KeyboardInterrupt

        return go

    monkeypatch.setattr(amsfe_sym.logs.write, "run_bag_filler", interrupted)
    extra = ["--bag"] if bag == "inside" else ["--bag", str(tmp / "b")]
    code = main([*SIM, "--out", str(tmp / "run"), *extra])
    assert code == (143 if signal_name == "SIGTERM" else 130)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"stopped by {signal_name}" in err[0], err
    assert "not written: --out " + str(tmp / "run") in err[0]
    if bag == "elsewhere":
        assert "--bag " + str(tmp / "b") in err[0]
    assert list(tmp.iterdir()) == []


def test_a_bag_elsewhere_is_written_with_its_run(tmp: Path, capsys) -> None:
    assert main([*SIM, "--out", str(tmp / "run"), "--bag", str(tmp / "b")]) == 0
    assert (tmp / "b" / MARKER).is_file() and any((tmp / "b").glob("*.mcap"))
    assert (tmp / "run" / "summary.json").is_file()
    comparison = ["simulate", "--compare", "amsfe,truth", "--duration", "0.05", "--no-progress"]
    assert (
        main([*comparison, "--no-plots", "--out", str(tmp / "cmp"), "--bag", str(tmp / "cb")]) == 0
    )
    assert sorted(p.name for p in (tmp / "cb").iterdir()) == [MARKER, "amsfe", "truth"]


# ----------------------------------------------- every JSON written parses strictly
def test_every_json_the_tool_writes_is_strict_json(tmp: Path, capsys) -> None:
    """summary.json (run, estimate), comparison.json, study.json, sweep.json, bench --json:
    each read by a parser that refuses NaN and Infinity."""
    assert main([*SIM, "--out", str(tmp / "run"), "--bag"]) == 0
    assert main(["estimate", str(tmp / "run" / "bag"), "--no-plots", "--out", str(tmp / "e")]) == 0
    cmp = [
        "simulate",
        "--compare",
        "amsfe,truth",
        "--duration",
        "0.05",
        "--no-progress",
        "--no-plots",
    ]
    assert main([*cmp, "--out", str(tmp / "cmp")]) == 0
    for key, out in ((("study", "--out"), "st"), (("sweep", "--out"), "sw")):
        assert main(CASES[key].argv(tmp, tmp / out)) == 0
    assert main(CASES[("bench", "--json")].argv(tmp, tmp / "bench.json")) == 0
    files = sorted(tmp.rglob("*.json"))
    names = {p.name for p in files}
    assert {"summary.json", "comparison.json", "study.json", "sweep.json", "bench.json"} <= names
    for p in files:
        _strict(p.read_text())


def test_a_nan_metric_is_null_with_its_reason_in_summary_json(
    tmp: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A run whose NEES is NaN (a filter that lost its covariance) wrote ``NaN`` into
    summary.json, which no strict parser reads; the real writer, fed that summary, writes
    null and records why."""
    import amsfe_sym.sim.record as record

    real = record.summarize

    def nan_nees(res):  # type: ignore[no-untyped-def]
        return {**real(res), "nees_mean": float("nan")}

    monkeypatch.setattr(record, "summarize", nan_nees)
    assert main([*SIM, "--out", str(tmp / "run")]) == 0
    doc = _strict((tmp / "run" / "summary.json").read_text())
    assert isinstance(doc, dict)
    assert doc["nees_mean"] is None and doc[NON_FINITE]["nees_mean"] == "nan"


@pytest.mark.slow
@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_real_signal_during_simulate_bag_leaves_nothing(tmp_path: Path, sig: str) -> None:
    """The same as a process: the signal mid-run (Python loop, 300 s of simulated time, a
    minute or more of wall time here: still running when the signal comes at 6 s) ends
    it with 130 / 143, one line naming the run folder and the bag as not written, and
    nothing left (no run folder without its bag, no hidden temporary)."""
    import signal
    import subprocess
    import sys
    import time

    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "amsfe_sym",
            *SIM[:3],
            "--duration",
            "300",
            "--runtime",
            "python",
            "--no-plots",
            "--no-progress",
            "--out",
            str(tmp_path / "run"),
            "--bag",
            str(tmp_path / "b"),
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(6.0)  # past the imports, inside the run
    proc.send_signal(getattr(signal, sig))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == (130 if sig == "SIGINT" else 143), err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "nothing half-written was kept; not written:" in lines[0], err
    assert f"--out {tmp_path / 'run'}" in lines[0] and f"--bag {tmp_path / 'b'}" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_folders_written_before_the_marker_are_the_tools(tmp: Path, capsys) -> None:
    """The study, claims and sweep folders in docs/data were written before the marker
    existed: they count as the tool's own (their documented commands re-run with --force),
    a folder of other files does not."""
    from amsfe_sym.apps.study.claims import is_claims_folder
    from amsfe_sym.apps.study.runner import is_study_folder
    from amsfe_sym.apps.sweep.engine import is_sweep_folder

    data = Path(__file__).resolve().parent.parent / "docs" / "data"
    assert is_claims_folder(data / "claims-paper-sim")
    assert is_study_folder(data / "study-paper-sim-estimators")
    assert is_sweep_folder(data / "sweeps" / "camera-delay")
    for check in (is_claims_folder, is_study_folder, is_sweep_folder):
        assert not check(data)
    argv = CASES[("study", "--out")].argv(tmp, tmp / "st")
    assert main(argv) == 0
    (tmp / "st" / MARKER).unlink()  # as an older amsfe wrote it
    capsys.readouterr()
    assert main(argv) == 2
    _one_line(capsys, "pass --force")
    assert main([*argv, "--force"]) == 0
    assert (tmp / "st" / MARKER).is_file()
