"""Bad input, as a new user would type it: one line (expected, found, fix), exit 2, no
traceback, nothing written (issue 10, deliverables 1 and 6).

Every case runs the CLI in-process (``amsfe_sym.apps.cli.main``) from an empty working folder
with ``$AMSFE_GENERATED_DIR`` pointing into it, and asserts the exit code, that stderr is
exactly one ``error: ...`` line holding the expected words, and that the folder holds only
the input files the case wrote.  A few run ``amsfe`` as a subprocess (exit codes, Ctrl-C).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.scenario import scenarios_dir
from tests.conftest import copy_build

BAD_URDFS = Path(__file__).parent / "data" / "bad_urdfs"
PAPER_SIM = (scenarios_dir() / "paper-sim.toml").read_text()


def _scenario(**edits: str) -> str:
    """paper-sim.toml with the line starting ``key =`` replaced by ``key = value``."""
    text = PAPER_SIM
    for key, value in edits.items():
        text, count = re.subn(rf"(?m)^{key} = .*$", f"{key} = {value}", text, count=1)
        assert count == 1, key
    return text


def _spec(extra: str) -> str:
    urdf = Path(__file__).parent.parent / "robots" / "paper_2link"
    return f'name = "bad"\nurdf = "{next(urdf.glob("*.urdf"))}"\n{extra}'


# (id, files to write {name: text}, argv, words the one line must contain)
CASES: list[tuple[str, dict[str, str], list[str], list[str]]] = [
    # ---- CLI numbers (argparse types)
    ("seed_negative", {}, ["simulate", "--seed", "-1"], ["--seed", "an integer >= 0", "'-1'"]),
    ("seed_text", {}, ["simulate", "--seed", "zero"], ["--seed", "'zero'"]),
    ("duration_nan", {}, ["simulate", "--duration", "nan"], ["--duration", "finite", "'nan'"]),
    ("duration_inf", {}, ["simulate", "--duration", "inf"], ["--duration", "'inf'"]),
    ("duration_zero", {}, ["simulate", "--duration", "0"], ["--duration", "> 0", "'0'"]),
    ("duration_negative", {}, ["simulate", "--duration", "-2"], ["--duration", "'-2'"]),
    # a NaN or inf initial state (was run, and reported as "the true state diverged")
    (
        "toml_q0_nan",
        {"s.toml": _scenario(q0="[nan, 0.5]")},
        ["simulate", "s.toml"],
        ["[plant] q0", "finite", "nan"],
    ),
    (
        "toml_estimate_qd_inf",
        {"s.toml": _scenario(qd="[inf, 0.0]")},
        ["simulate", "s.toml"],
        ["[estimate0] qd", "finite", "inf"],
    ),
    (
        "set_q0_nan",
        {},
        ["simulate", "--set", "plant.q0=[nan, 0.5]"],
        ["[plant] q0", "finite", "nan"],
    ),
    # shorter than one period (summary.json held NaN), or records beyond memory (a 74 GiB
    # allocation traceback): refused before anything is built, with the bytes
    ("duration_tiny", {}, ["simulate", "--duration", "1e-9"], ["duration", "T = 0.001", "1e-09"]),
    ("duration_huge", {}, ["simulate", "--duration", "1e7"], ["duration", "GiB", "bytes"]),
    # ---- one seed rule (issue 25): 0 .. 2^63 - 1, so every config.toml re-runs
    ("seed_2_64", {}, ["simulate", "--seed", str(2**64)], ["--seed", f"<= {2**63 - 1}"]),
    ("seed_2_63", {}, ["simulate", "--seed", str(2**63)], ["--seed", f"<= {2**63 - 1}"]),
    (
        "toml_seed_2_63",
        {"s.toml": _scenario(seed=str(2**63))},
        ["simulate", "s.toml"],
        ["seed", "2^63 - 1", str(2**63)],
    ),
    ("study_first_seed_2_64", {}, ["study", "--first-seed", str(2**64)], ["--first-seed"]),
    ("check_samples_zero", {}, ["check", "--samples", "0"], ["--samples", ">= 1", "cannot fail"]),
    ("check_samples_negative", {}, ["check", "--samples", "-3"], ["--samples", "'-3'"]),
    ("check_seed_text", {}, ["check", "--seed", "x"], ["--seed", "'x'"]),
    ("study_seeds_zero", {}, ["study", "--seeds", "0"], ["--seeds", ">= 1"]),
    ("study_workers_zero", {}, ["study", "--workers", "0"], ["--workers", ">= 1"]),
    ("study_first_seed_negative", {}, ["study", "--first-seed", "-1"], ["--first-seed"]),
    ("study_duration_nan", {}, ["study", "--duration", "nan"], ["--duration"]),
    ("bench_repeat_zero", {}, ["bench", "--repeat", "0"], ["--repeat", ">= 1"]),
    ("bench_rounds_text", {}, ["bench", "--rounds", "abc"], ["--rounds", "'abc'"]),
    ("bench_duration_zero", {}, ["bench", "--duration", "0"], ["--duration"]),
    ("lock_value_text", {}, ["generate", "--lock", "j1=abc"], ["--lock", "JOINT=VALUE"]),
    ("unknown_option", {}, ["simulate", "--bogus"], ["unrecognized arguments: --bogus"]),
    ("unknown_command", {}, ["simulte"], ["invalid choice", "simulte"]),
    # ---- names that do not exist
    ("scenario_unknown", {}, ["simulate", "no-such-scenario"], ["no-such-scenario", "paper-sim"]),
    ("robot_unknown", {}, ["generate", "no_such_robot"], ["no_such_robot"]),
    # ---- scenario TOML: types
    (
        "toml_seed_string",
        {"s.toml": _scenario(seed='"zero"')},
        ["simulate", "s.toml"],
        ["seed", "an integer", "'zero' (a string)"],
    ),
    (
        "toml_duration_string",
        {"s.toml": _scenario(duration='"ten"')},
        ["simulate", "s.toml"],
        ["duration", "a number", "'ten' (a string)"],
    ),
    (
        "toml_q0_string",
        {"s.toml": _scenario(q0='"zero"')},
        ["simulate", "s.toml"],
        ["[plant] q0", "a list of numbers", "'zero'"],
    ),
    (
        "toml_q0_strings_in_list",
        {"s.toml": _scenario(q0='["a", "b"]')},
        ["simulate", "s.toml"],
        ["q0", "a list of numbers"],
    ),
    (
        "toml_seed_float",
        {"s.toml": _scenario(seed="1.0")},
        ["simulate", "s.toml"],
        ["seed", "write seed = 1"],
    ),
    (
        "toml_seed_negative",
        {"s.toml": _scenario(seed="-3")},
        ["simulate", "s.toml"],
        ["seed", ">= 0", "-3"],
    ),
    (
        "toml_period_float",
        {"s.toml": _scenario(jitter_steps="2.0")},
        ["simulate", "s.toml"],
        ["[camera] jitter_steps", "write jitter_steps = 2"],
    ),
    (
        "toml_bool_as_int",
        {"s.toml": _scenario(round_to_pixel="1")},
        ["simulate", "s.toml"],
        ["round_to_pixel", "true or false"],
    ),
    (
        "toml_std_string",
        {"s.toml": _scenario(std='{ q = "a" }')},
        ["simulate", "s.toml"],
        ["std.q", "a number"],
    ),
    (
        "toml_name_number",
        {"s.toml": _scenario(name="3")},
        ["simulate", "s.toml"],
        ["name", "a string"],
    ),
    # ---- scenario TOML: values
    (
        "toml_duration_negative",
        {"s.toml": _scenario(duration="-1.0")},
        ["simulate", "s.toml"],
        ["duration", "> 0", "-1.0", "simulated time"],
    ),
    (
        "toml_duration_nan",
        {"s.toml": _scenario(duration="nan")},
        ["simulate", "s.toml"],
        ["duration", "nan"],
    ),
    (
        "toml_filter_std_zero",
        {
            "s.toml": PAPER_SIM.replace(
                "[filter]\nlink_torque_std = 0.1", "[filter]\nlink_torque_std = 0.0"
            )
        },
        ["simulate", "s.toml"],
        ["link_torque_std", "positive definite"],
    ),
    (
        "toml_integrator",
        {"s.toml": _scenario(integrator='"euler"')},
        ["simulate", "s.toml"],
        ["integrator", "'euler'", "rk4"],
    ),
    (
        "toml_motor0",
        {"s.toml": _scenario(motor0='"nope"')},
        ["simulate", "s.toml"],
        ["motor0", "'nope'", "equilibrium"],
    ),
    (
        "toml_unknown_key",
        {"s.toml": PAPER_SIM + "\n[extra]\nx = 1\n"},
        ["simulate", "s.toml"],
        ["unknown ['extra']"],
    ),
    (
        "toml_unknown_section_key",
        {"s.toml": PAPER_SIM.replace("[plant]\n", "[plant]\nq9 = 1\n")},
        ["simulate", "s.toml"],
        ["[plant]", "unknown ['q9']"],
    ),
    (
        "toml_syntax",
        {"s.toml": PAPER_SIM + "\nthis is not toml\n"},
        ["simulate", "s.toml"],
        ["not valid TOML"],
    ),
    (
        "toml_no_plant",
        {"s.toml": PAPER_SIM.replace("[plant]", "[plant_]")},
        ["simulate", "s.toml"],
        ["unknown ['plant_']"],
    ),
    (
        "toml_robot_unknown",
        {"s.toml": _scenario(robot='"nosuchrobot"')},
        ["simulate", "s.toml"],
        ["nosuchrobot"],
    ),
    # ---- scenario vectors vs the robot: every one in one message, before generating
    (
        "vectors_all_together",
        {"s.toml": _scenario(q0="[0.5, 0.5, 0.1]", q="[0.9]")},
        ["simulate", "s.toml"],
        ["expected 2 values", "[plant] q0 has 3", "[estimate0] q has 1"],
    ),
    (
        "vectors_theta",
        {"s.toml": _scenario(theta="[0.1, 0.2, 0.3]")},
        ["simulate", "s.toml"],
        ["[estimate0] theta has 3"],
    ),
    # ---- URDF topology and defects (generate)
    *[
        (f"urdf_{f}", {}, ["generate", str(BAD_URDFS / f"{f}.urdf")], words)
        for f, words in [
            ("two_parents", ["link 'link2'", "one parent joint", "'joint2' and 'joint3'"]),
            ("kinematic_loop", ["kinematic loop", "link1", "a URDF is a tree"]),
            ("duplicate_joint", ["joint 'joint1'", "unique joint names", "2 times"]),
            ("duplicate_link", ["link 'link1'", "unique link names"]),
            ("self_parent", ["joint 'joint2'", "differ"]),
            ("two_roots", ["island", "one root link"]),
            ("malformed_xml", ["well-formed XML"]),
            ("missing_link", ["ghost_link"]),
            ("negative_mass", ["mass"]),
            ("floating_joint", ["float_joint"]),
        ]
    ],
    # ---- robot spec
    (
        "spec_unknown_key",
        {"r/robot.toml": _spec("colour = 1\n")},
        ["generate", "r/robot.toml"],
        ["colour"],
    ),
    (
        "spec_ks_length",
        {"r/robot.toml": _spec("[actuators]\nKs = [1.0]\n")},
        ["generate", "r/robot.toml"],
        ["Ks", "expected 2 values", "found 1"],
    ),
    (
        "spec_integrator",
        {"r/robot.toml": _spec('[model]\nintegrator = "euler"\n')},
        ["generate", "r/robot.toml"],
        ["integrator", "'euler'"],
    ),
    # ---- issue 37 item 5: every option bounded before work starts (a hang leaving a .lock,
    # tracebacks, a library named T0pus for every period below 0.5 ns, a 2 TiB buffer)
    ("period_1e9", {}, ["generate", "--period", "1e9"], ["--period", "[1e-06, 10] s"]),
    ("period_1e300", {}, ["generate", "--period", "1e300"], ["--period", "[1e-06, 10] s"]),
    ("period_1e-320", {}, ["generate", "--period", "1e-320"], ["--period", "1e-320"]),
    ("period_sub_ns", {}, ["generate", "--period", "4e-10"], ["--period", "[1e-06, 10] s"]),
    ("substeps_1e10", {}, ["generate", "--substeps", "10000000000"], ["--substeps", "<= 256"]),
    (
        "period_needs_too_many_substeps",
        {},
        ["generate", "--period", "9"],
        ["--period", "1 to 256 rk4 steps", "--period 6.6 or shorter"],
    ),
    (
        "spec_T_tiny",
        {"r/robot.toml": _spec("[model]\nT = 1e-12\n")},
        ["generate", "r/robot.toml"],
        ["[model] T", "[1e-06, 10]"],
    ),
    (
        "spec_model_substeps_huge",
        {"r/robot.toml": _spec("[model]\nmodel_substeps = 100000\n")},
        ["generate", "r/robot.toml"],
        ["model_substeps", "[1, 256]"],
    ),
    (
        "buffer_steps_2e9",
        {},
        ["simulate", "--set", "filter.buffer_steps=2000000000"],
        ["buffer_steps", "[1, 100000]"],
    ),
    (
        "encoder_q_std_1e300",
        {},
        ["simulate", "--set", "filter.encoder_q_std=1e300"],
        ["encoder_q_std", "<= 1e+06"],
    ),
    ("play_rate_1e-9", {"x.mcap": ""}, ["play", "x.mcap", "--rate", "1e-9"], ["--rate", "0.001"]),
]


@pytest.fixture()
def workdir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty working folder that also receives generated libraries."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("AMSFE_GENERATED_DIR", str(tmp_path / "generated"))
    return tmp_path


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize(
    ("files", "argv", "words"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input_one_line_exit_2_nothing_written(
    files: dict[str, str],
    argv: list[str],
    words: list[str],
    workdir: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    for name, text in files.items():
        (workdir / name).parent.mkdir(parents=True, exist_ok=True)
        (workdir / name).write_text(text)
    before = _files(workdir)
    code = main([*argv, "--out", str(workdir / "out")] if argv[0] == "simulate" else argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert "Fix: fix it" not in lines[0]
    assert _files(workdir) == before  # nothing written: no run folder, no library, no temp


def test_at_least_thirty_cases() -> None:
    assert len(CASES) >= 30


def test_duration_message_is_not_about_covariances(
    workdir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (workdir / "s.toml").write_text(_scenario(duration="-1.0"))
    assert main(["simulate", "s.toml"]) == 2
    assert "covariance" not in capsys.readouterr().err


def _amsfe(*args: str, **kw: object) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "amsfe_sym.apps.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **kw,  # type: ignore[call-overload]
    )


@pytest.mark.parametrize(
    ("argv", "code"),
    [(["simulate", "--seed", "-1"], 2), (["check", "--samples", "0"], 2), (["--help"], 0)],
)
def test_exit_codes_as_a_process(argv: list[str], code: int, tmp_path: Path) -> None:
    proc = _amsfe(*argv, cwd=tmp_path)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "stage",
    [
        "build lock",  # the URDF load: the Pinocchio and yourdfpy/trimesh imports (swallowed)
        "symbolic model built",  # CasADi code generation
        "compiling (",  # the compiler
    ],
)
def test_ctrl_c_during_generate_leaves_nothing(tmp_path: Path, stage: str) -> None:
    """SIGINT at each stage of the UR5's build, sent as soon as the stage has begun (the
    build lock exists: the load starts; or generate's progress line): no sleeps, because the
    signal is held and raised at the build's next checkpoint, so where it lands in a stage
    does not matter.  Exit 130, one line, no folder left behind."""
    out = tmp_path / "gen"
    proc = _amsfe("generate", "ur5", "--out", str(out), "--force")
    assert proc.stderr is not None
    seen = []
    if stage == "build lock":
        deadline = time.monotonic() + 120
        while not (out / ".ur5.lock").exists() and proc.poll() is None:
            assert time.monotonic() < deadline
            time.sleep(0.005)
    else:
        for line in proc.stderr:  # the progress lines come before the stage's work
            seen.append(line)
            if stage in line:
                break
    assert proc.poll() is None, f"generate ended before {stage!r}: {seen}"
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=120)
    err = "".join(seen) + rest
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("[amsfe]")]
    assert proc.returncode == 130, err
    assert "Traceback" not in err
    assert len(lines) == 1 and lines[0].startswith("interrupted: amsfe generate"), err
    assert not out.exists() or list(out.iterdir()) == []


def test_damaged_library_is_rebuilt_by_check(
    workdir: Path, capsys: pytest.CaptureFixture[str], paper_1link_build: Path
) -> None:
    """A library with flipped bytes (same size) used to segfault check; now it is rebuilt.
    (The library: a copy of the session's build, tests/conftest.py's ``paper_1link_build``.)"""
    copy_build(paper_1link_build, workdir / "generated")
    assert main(["generate", "paper_1link"]) == 0
    assert "up to date (cached)" in capsys.readouterr().out  # the copy is the cache
    lib = workdir / "generated" / "paper_1link" / "libpaper_1link.so"
    data = bytearray(lib.read_bytes())
    for i in range(len(data) // 2, len(data) // 2 + 64):
        data[i] ^= 0xFF
    damaged = lib.with_name(lib.name + ".damaged")  # a new inode: the old one is mapped here
    damaged.write_bytes(bytes(data))
    os.replace(damaged, lib)
    assert main(["generate", "paper_1link"]) == 0
    assert "generated in" in capsys.readouterr().out  # not "up to date (cached)"
    assert main(["check", "paper_1link", "--samples", "2"]) == 0
    assert os.path.getsize(lib) == len(data)


# ---- run folders: complete or absent; --out never silently overwrites
RUN = ["simulate", "--controller", "amsfe", "--duration", "0.05", "--no-progress", "--no-plots"]


def test_out_at_an_existing_file_is_refused(tmp_path: Path, capsys) -> None:
    target = tmp_path / "notes.txt"
    target.write_text("mine")
    for extra in ([], ["--force"]):
        assert main([*RUN, "--out", str(target), *extra]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and "an existing file" in lines[0], lines
    assert target.read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_out_at_an_existing_run_folder_needs_force(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    assert main([*RUN, "--out", str(out)]) == 0
    (out / "old-figure.png").write_text("from an older run")
    before = (out / "timeseries.csv").read_text()
    assert main([*RUN, "--out", str(out), "--seed", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "an existing folder" in err[0] and "--force" in err[0]
    assert (out / "timeseries.csv").read_text() == before  # untouched
    assert main([*RUN, "--out", str(out), "--seed", "5", "--force"]) == 0
    assert not (out / "old-figure.png").exists()  # replaced as a whole, not mixed
    assert (out / "timeseries.csv").read_text() != before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no hidden leftovers


def test_a_failure_while_writing_leaves_no_run_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import amsfe_sym.apps.plots.run

    def boom(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(amsfe_sym.apps.plots.run, "plot_run", boom)
    out = tmp_path / "run"
    args = ["simulate", "--controller", "amsfe", "--duration", "0.05", "--no-progress"]
    assert main([*args, "--out", str(out)]) == 130
    assert list(tmp_path.iterdir()) == []


def test_force_never_replaces_a_folder_the_tool_did_not_write(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """``--out DIR --force`` deleted DIR whatever it held (a thesis folder was replaced by a
    run); ``--out . --force`` simulated, then failed.  Both are refused before the run."""
    mine = tmp_path / "thesis"
    (mine / "robots").mkdir(parents=True)
    (mine / "thesis.tex").write_text("months of work")
    assert main([*RUN, "--out", str(mine), "--force"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "did not write" in err[0], err
    assert (mine / "thesis.tex").read_text() == "months of work"
    monkeypatch.chdir(mine)
    assert main([*RUN, "--out", ".", "--force"]) == 2
    assert (mine / "thesis.tex").read_text() == "months of work"
    assert sorted(p.name for p in mine.iterdir()) == ["robots", "thesis.tex"]
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main([*RUN, "--out", str(empty), "--force"]) == 0  # an empty folder is fine


def test_sigterm_is_handled_like_ctrl_c(tmp_path: Path) -> None:
    """SIGTERM mid-run: exit 143, one line, no run folder and no hidden temporary left.
    On a loaded machine the 6 s may still be inside the command's imports: that is one line
    and exit 143 too (``python -m amsfe_sym`` handles SIGTERM from its first line; the
    signal used to kill the process there, exit -15, and fail this test at random)."""
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "run"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "amsfe_sym",
            *RUN[:-2],
            "--duration",
            "60",
            "--runtime",
            "python",
            "--no-plots",
            "--no-progress",
            "--out",
            str(out),
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(6.0)  # past the imports, inside the run
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "stopped by SIGTERM" in lines[0], err
    assert list(tmp_path.iterdir()) == []


def test_output_folders_follow_the_umask_and_clean_a_killed_runs_leftovers(
    tmp_path: Path,
) -> None:
    import os

    stale = tmp_path / ".run.tmp-999999999-abc"  # a SIGKILLed run's folder (its pid is gone)
    stale.mkdir()
    (stale / ".amsfe-tmp").write_text("amsfe_sym temporary folder; pid 999999999; start 1\n")
    (stale / "timeseries.csv").write_text("half")
    old = os.umask(0o022)
    try:
        assert main([*RUN, "--out", str(tmp_path / "run")]) == 0
    finally:
        os.umask(old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert (tmp_path / "run").stat().st_mode & 0o777 == 0o755


# ---- issue 25: paths the tool writes (the full rule is walked in tests/test_outputs.py)
@pytest.fixture()
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An empty working folder (generated libraries stay in the session's shared cache)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _tree(folder: Path) -> dict[str, bytes | None]:
    return {
        str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
        for p in sorted(folder.rglob("*"))
    }


def _err_line(capsys: pytest.CaptureFixture[str]) -> str:
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    return lines[0]


def test_bag_never_replaces_what_the_user_did_not_hand_it(here: Path, capsys) -> None:
    """``simulate --out RUN --bag DIR`` replaced whatever was at DIR without --force: a
    folder of the user's, a file (only a hidden ``.NAME.old-*`` copy was left), the run
    folder itself (``--bag RUN``), an earlier estimate folder.  All refused, untouched."""
    assert main([*RUN, "--out", "earlier", "--bag"]) == 0
    assert main(["estimate", "earlier/bag", "--no-plots", "--out", "est"]) == 0
    (here / "mine").mkdir()
    (here / "mine" / "data.csv").write_text("1,2,3")
    (here / "notes.txt").write_text("mine")
    capsys.readouterr()
    before = _tree(here)
    for bag, words in (
        ("mine", ["did not write"]),
        ("notes.txt", ["an existing file"]),
        ("run", ["apart from --out run"]),
        ("est", ["an existing folder", "--force"]),
    ):
        assert main([*RUN, "--out", "run", "--bag", bag]) == 2, bag
        line = _err_line(capsys)
        assert all(w in line for w in words), (bag, line)
    assert _tree(here) == before  # nothing replaced, no hidden copies, no run folder
    assert main([*RUN, "--out", "run", "--bag", "mine", "--force"]) == 2
    assert "did not write" in _err_line(capsys)
    assert _tree(here) == before


def test_estimate_never_writes_over_its_own_log(here: Path, capsys) -> None:
    """``amsfe estimate BAG --out BAG --force`` deleted the input log (the bag carries the
    marker --force trusts) and wrote the estimate in its place, exit 0."""
    assert main([*RUN, "--out", "run", "--bag"]) == 0
    capsys.readouterr()
    before = _tree(here)
    for out in ("run/bag", "run", "run/bag/estimate"):
        assert main(["estimate", "run/bag", "--out", out, "--force", "--no-plots"]) == 2
        line = _err_line(capsys)
        assert "the input run/bag" in line and "even with --force" in line, line
    mcap = next((here / "run" / "bag").glob("*.mcap")).relative_to(here)
    assert main(["estimate", str(mcap), "--out", "run/bag/est", "--no-plots"]) == 2
    assert "the input run/bag" in _err_line(capsys)  # the .mcap's bag folder is the log
    assert _tree(here) == before


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        ([*RUN, "--out", "notes.txt/run"], ["notes.txt is a file"]),
        ([*RUN, "--out", "/proc/amsfe/run"], ["not writable"]),
        ([*RUN, "--out", "run", "--bag", "/sys/amsfe-bag"], ["--bag", "not writable"]),
        (["bench", "--skip", "calls", "--json", "folder"], ["--json folder", "existing folder"]),
    ],
    ids=["out_under_a_file", "out_read_only_parent", "bag_under_sys", "bench_json_folder"],
)
def test_path_problems_are_found_before_any_work(here: Path, capsys, argv, words) -> None:
    """Found only after the whole run, with a traceback, before (issue 25): now one line
    before anything runs or is generated (no library, no output on stdout)."""
    (here / "notes.txt").write_text("mine")
    (here / "folder").mkdir()
    before = _tree(here)
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and all(w in lines[0] for w in words), lines
    assert out == ""
    assert _tree(here) == before


@pytest.mark.parametrize("seed", [0, 2**63 - 1])
def test_config_toml_reruns_for_the_edge_seeds(here: Path, seed: int) -> None:
    """A seed ``simulate`` accepts is one its own config.toml re-runs (2^64 was accepted,
    then refused on the re-run): same seed, same time series."""
    assert main([*RUN, "--seed", str(seed), "--out", "a"]) == 0
    assert f"seed = {seed}" in (here / "a" / "config.toml").read_text()
    rerun = ["simulate", "a/config.toml", "--no-progress", "--no-plots", "--out", "b"]
    assert main(rerun) == 0
    assert (here / "a" / "timeseries.csv").read_text() == (
        here / "b" / "timeseries.csv"
    ).read_text()


@pytest.mark.parametrize("jobs", ["abc", "0", "-1"])
def test_bad_build_jobs_is_one_line(here: Path, capsys, monkeypatch, jobs: str) -> None:
    """``AMSFE_BUILD_JOBS=abc`` was ignored without a word."""
    monkeypatch.setenv("AMSFE_BUILD_JOBS", jobs)
    assert main(["generate", "paper_1link"]) == 2
    line = _err_line(capsys)
    assert "$AMSFE_BUILD_JOBS" in line and repr(jobs) in line and "export" in line
    assert list(here.iterdir()) == []


def test_a_log_whose_scenario_is_not_toml_is_one_line(here: Path, capsys) -> None:
    """A log config whose ``scenario_toml`` is not TOML ended in a traceback: the bag of a
    real run, rewritten with that one message changed."""
    import json

    from rosbags.rosbag2 import Reader, StoragePlugin, Writer

    from amsfe_sym.logs.source import typestore

    assert main([*RUN, "--out", "run", "--bag"]) == 0
    ts = typestore()
    with (
        Reader(here / "run" / "bag") as r,
        Writer(here / "broken", version=9, storage_plugin=StoragePlugin.MCAP) as w,
    ):
        conns = {}
        for c, t, raw in r.messages():
            if c.topic not in conns:
                conns[c.topic] = w.add_connection(c.topic, c.msgtype, typestore=ts)
            if c.topic == "/amsfe/config":
                cfg = json.loads(ts.deserialize_cdr(raw, c.msgtype).data)
                cfg["scenario_toml"] = "robot = [unclosed"
                msg = ts.types["std_msgs/msg/String"](data=json.dumps(cfg))
                raw = ts.serialize_cdr(msg, c.msgtype)
            w.write(conns[c.topic], t, raw)
    capsys.readouterr()
    before = _tree(here)
    assert main(["estimate", "broken", "--no-plots", "--out", "est"]) == 2
    line = _err_line(capsys)
    assert "scenario_toml" in line and "not TOML" in line and "--scenario" in line, line
    assert _tree(here) == before
