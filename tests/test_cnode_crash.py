"""What the C node says when it dies, and its sanitizer build (issue 34: one CI run's C node
exited by SIGSEGV after its first line, and nothing said where).

- A fatal signal is reported on stderr with the stack (``amsfe_program_start`` in
  ``ros/c/amsfe_rcl.c``), the exit status stays the signal's; stdout is line-buffered, so
  every line printed before the death reaches a pipe.
- ``$AMSFE_CNODE_EXTRA_FLAGS`` (tools/cnode_starts.py ``--sanitize``) keys a build of its
  own: the normal build's key and command are unchanged without it.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
from pathlib import Path

import pytest

from amsfe_sym.codegen import library_for
from amsfe_sym.scenario import load_scenario


def _paper() -> tuple[object, object]:
    pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (pip install -e '.[ros]')")
    sc = load_scenario("paper-sim")
    return sc, library_for(sc)


def _line(stream: object, timeout: float) -> str:
    """One line of a pipe within ``timeout`` [s] ('' when none came)."""
    fd = stream.fileno()  # type: ignore[attr-defined]
    ready, _, _ = select.select([fd], [], [], timeout)
    return stream.readline() if ready else ""  # type: ignore[attr-defined]


def test_a_fatal_signal_is_reported_with_its_stack_and_the_lines_before_it(
    tmp_path: Path,
) -> None:
    """The C node's live loop (``--replay`` on a FIFO: no middleware) prints its tick 0 to a
    pipe at once (a block-buffered pipe held it until the exit), then SIGSEGV ends it: exit
    -11, one line naming the signal and the stack on stderr."""
    from amsfe_sym.ros.cnode import build_node, write_params
    from amsfe_sym.topics import TopicSpec

    sc, lib = _paper()
    opts = {"end_k": -1, "std_every": 10, "hold": "gravity", "encoder_timeout": 0.5,
            "subscriber_wait": 1.0, "record": None, "sched_priority": 0}  # fmt: skip
    params = write_params(tmp_path, sc, lib, TopicSpec(), controller=True, options=opts)
    exe = build_node(lib).path
    fifo = tmp_path / "events"
    os.mkfifo(fifo)
    node = subprocess.Popen([str(exe), str(params), "--replay", str(fifo)], text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip
    try:
        # opened once the node opens it: after its start (the handlers installed)
        with fifo.open("w") as events:
            events.write("enc 1000000000 1000000000 " + " ".join(["0.0"] * 2 * lib.n) + "\n")
            events.flush()
            first = _line(node.stdout, 60.0)
            assert first.startswith("tick 0 "), first
            node.send_signal(signal.SIGSEGV)
            _, err = node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()
            node.wait()
    assert node.returncode == -signal.SIGSEGV, err
    assert "error: amsfe_node: killed by SIGSEGV; its stack:\n" in err, err
    assert any(line.startswith(str(exe)) for line in err.splitlines()), err


def test_extra_flags_key_a_build_of_their_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """Without ``$AMSFE_CNODE_EXTRA_FLAGS`` the build's inputs (its key) and command have no
    extra flags; with them, the inputs name them (another key) and the command carries them
    after the normal flags."""
    from amsfe_sym.codegen.cache import compiler
    from amsfe_sym.ros.cnode_build import (
        CNODE_CFLAGS,
        EXTRA_FLAGS_ENV,
        _command,
        build_inputs,
        ros_paths,
    )

    _, lib = _paper()
    ros, cc = ros_paths(), compiler()
    monkeypatch.delenv(EXTRA_FLAGS_ENV, raising=False)
    plain = build_inputs(lib, "amsfe_node", ros, cc)  # type: ignore[arg-type]
    assert "extra_flags" not in plain
    monkeypatch.setenv(EXTRA_FLAGS_ENV, "-g -fsanitize=address,undefined")
    sanitized = build_inputs(lib, "amsfe_node", ros, cc)  # type: ignore[arg-type]
    assert sanitized == {**plain, "extra_flags": ["-g", "-fsanitize=address,undefined"]}
    flags = ("-g", "-fsanitize=address")
    cmd = _command(cc, lib, ros, [], Path("out"), Path("gen"), (), flags)  # type: ignore[arg-type]
    at = cmd.index(CNODE_CFLAGS[-1])
    assert cmd[at + 1 : at + 3] == list(flags)
    assert not set(flags) & set(_command(cc, lib, ros, [], Path("out"), Path("gen")))  # type: ignore[arg-type]
