"""The command line, called as ``main([...])``."""

from __future__ import annotations

import pytest

from amsfe_sym.apps.cli import main


def test_generate_without_arguments_is_cached(capsys, libraries) -> None:
    libraries.get("paper_2link")  # built once for the session
    assert main(["generate"]) == 0
    assert "up to date (cached)" in capsys.readouterr().out


def test_check_prints_a_passing_table(capsys, libraries) -> None:
    libraries.get("paper_2link")
    assert main(["check", "--samples", "5"]) == 0
    out = capsys.readouterr().out
    for name in ("mass_matrix", "transition_jacobian", "transition_inverse", "camera_jacobian"):
        assert name in out
    assert "FAIL" not in out and "all 12 functions pass" in out


def test_bad_robot_exits_2_with_one_clear_line(capsys, tmp_path) -> None:
    assert main(["generate", str(tmp_path / "nope.urdf"), "--out", str(tmp_path / "gen")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "expected" in err and "Fix:" in err
    assert not (tmp_path / "gen").exists()


def test_lock_argument_parsing(tmp_path, capsys) -> None:
    assert main(["generate", "--lock", "j1=abc"]) == 2
    assert "JOINT=VALUE" in capsys.readouterr().err


def test_version_answers(capsys) -> None:
    """``amsfe --version`` prints the toolkit's version and exits 0, as every tool does."""
    import amsfe_sym

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip().startswith(f"amsfe {amsfe_sym.__version__}")


def test_package_root_names_resolve_lazily() -> None:
    """``amsfe_sym.generate`` and friends are the codegen functions, imported on first use."""
    import subprocess
    import sys

    code = (
        "import sys, amsfe_sym; a = 'casadi' in sys.modules; "
        "from amsfe_sym.codegen import generate; "
        "print(a, amsfe_sym.generate is generate, amsfe_sym.load_library.__module__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True", "amsfe_sym.codegen.libraries"]


def test_lock_refuses_a_non_finite_value(capsys) -> None:
    """``--lock joint2=nan`` used to build and cache a library that returns NaN everywhere."""
    assert main(["generate", "--lock", "joint2=nan"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "finite" in err and "\n" not in err


@pytest.fixture
def keep_sigterm():
    """The entry installs a SIGTERM handler: put the test process's back."""
    import signal

    old = signal.getsignal(signal.SIGTERM)
    yield
    signal.signal(signal.SIGTERM, old)


def test_the_console_script_starts_through_the_guarded_entry(
    monkeypatch, capsys, keep_sigterm
) -> None:
    """``amsfe`` (the console script) and ``python -m amsfe_sym`` share one entry, which
    handles Ctrl-C / SIGTERM while the command line's modules load (issue 20)."""
    from pathlib import Path

    import tomllib

    import amsfe_sym.__main__ as entry

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert project["project"]["scripts"]["amsfe"] == "amsfe_sym.__main__:run"
    monkeypatch.setattr("sys.argv", ["amsfe", "--version"])
    try:
        code = entry.run()
    except SystemExit as exc:  # argparse's --version exits
        code = exc.code
    assert code == 0
    assert "amsfe" in capsys.readouterr().out


def test_an_interrupt_while_the_command_line_loads_is_one_line(
    monkeypatch, capsys, keep_sigterm
) -> None:
    import types

    import amsfe_sym.__main__ as entry

    class Loading(types.ModuleType):
        def __getattr__(self, name: str) -> object:
            raise KeyboardInterrupt  # Ctrl-C while the module loads

    monkeypatch.setitem(__import__("sys").modules, "amsfe_sym.apps.cli", Loading("cli"))
    assert entry.run() == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Ctrl-C" in err[0] and "nothing was written" in err[0]


def test_a_closed_stdout_is_one_line_and_exit_141(libraries) -> None:
    """``amsfe ... | head``: the reader closes the pipe before the command writes (here
    ``generate``, cached, whose lines reach the pipe at exit's flush); the command ends with
    one line on stderr and 128 + SIGPIPE, no traceback, nothing at exit."""
    import subprocess
    import sys

    proc = subprocess.Popen(
        [sys.executable, "-m", "amsfe_sym", "generate"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None
    proc.stdout.close()  # before the interpreter has even loaded the command line
    _, err = proc.communicate(timeout=120)
    text = err.decode()
    assert proc.returncode == 141, text
    assert "broken pipe" in text and "Traceback" not in text and "Exception ignored" not in text
    assert len(text.strip().splitlines()) == 1


def test_a_pipe_closed_under_a_command_says_what_was_kept(monkeypatch, capsys) -> None:
    from amsfe_sym.apps import cli

    def closed(args: object) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(cli, "_generate", closed)
    assert main(["generate"]) == cli.BROKEN_PIPE
    err = capsys.readouterr().err
    assert err.startswith("stopped: amsfe generate's output was closed (broken pipe)")
    assert "nothing half-written was kept" in err


def test_a_crash_under_amsfe_prints_the_python_stack() -> None:
    """A fatal signal in the ``amsfe`` process (a crash in a compiled extension: rclpy, the
    middleware) prints the Python stack of its threads on stderr (faulthandler, enabled by
    the entry point) and the process dies by the signal as before: here a SIGSEGV after
    ``amsfe --version`` ran through the entry point, in a process of its own."""
    import os
    import signal
    import subprocess
    import sys

    crash = (
        "import ctypes, sys\n"
        "import amsfe_sym.__main__ as entry\n"
        "sys.argv = ['amsfe', '--version']\n"
        "try:\n"
        "    entry.run()\n"
        "except SystemExit:\n"
        "    pass\n"
        "ctypes.string_at(0)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONFAULTHANDLER"}
    proc = subprocess.run(
        [sys.executable, "-c", crash], capture_output=True, text=True, env=env, timeout=120
    )
    assert proc.returncode == -signal.SIGSEGV, (proc.returncode, proc.stderr)
    assert "Fatal Python error: Segmentation fault" in proc.stderr, proc.stderr
    assert "string_at" in proc.stderr  # the Python frame that crashed


def test_node_refuses_an_unknown_controller_before_anything(capsys, tmp_path, monkeypatch) -> None:
    """``amsfe node --controller NAME`` with a name no controller has: exit 2 and one line
    naming the controllers, before the node says or builds anything (it printed its
    "waiting for encoders" first, then failed)."""
    monkeypatch.chdir(tmp_path)
    code = main(["node", "paper-sim", "--controller", "nosuch", "--record", "rec"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "", out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "controller name" in lines[0] and "'amsfe'" in lines[0], err
    assert list(tmp_path.iterdir()) == []
