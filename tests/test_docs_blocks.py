"""Every code block of the docs runs: README.md and docs/**/*.md, as a reader would paste it.

A fenced block whose language is ``bash``/``sh`` runs under ``bash -e`` in a temporary folder
(the repository's ``robots/``, ``scenarios/``, ``sweeps/``, ``tools/``, ``examples/`` and
``docs/`` linked in, the running interpreter's venv first on PATH and as ``.venv``); a
``python`` block runs with the same interpreter there. The blocks of one page run in order in
one folder, so a tutorial's later step uses what an earlier one wrote. Only the exit status
is asserted (a block's output is checked where the docs show it: tests/test_docs_numbers.py).

The fence's info string says what CI does with a block (after the language):

    ```bash                      run in CI
    ```bash {ci=slow}            run in CI, the page's test marked slow (more than a few s)
    ```bash {ci=ros}             run where the [ros] extra is installed (marked ros)
    ```bash {ci=nightly: TESTS}  run with --nightly only: a test CI runs (TESTS names it,
                                 tests/FILE.py::test_name, checked to exist) runs the
                                 same commands (docs/how-to/tests.md)
    ```bash {ci=skip: REASON}    not run; the reason is required and shown as the skip

Blocks in other languages (text, toml, c, ...) are shown, not run.
"""

from __future__ import annotations

import json
import os
import queue
import re
import shutil
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RUN_LANGS = {"bash": "bash", "sh": "bash", "shell": "bash", "python": "python", "py": "python"}
LINKED = ("robots", "scenarios", "sweeps", "tools", "examples", "docs", "tests")
_FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([^`\s{]*)\s*(\{.*\})?\s*$")
_CI = re.compile(r"^\{ci=(run|slow|ros|nightly|skip)(?::\s*(.*))?\}$")
#: A test a ``{ci=nightly: ...}`` block names: the one that runs its commands in CI.
_TEST_REF = re.compile(r"tests/[\w/]+\.py::test_\w+")
BLOCK_TIMEOUT_S = 600  # a hung block fails instead of hanging CI; not a timing assertion


@dataclass(frozen=True)
class Block:
    page: str  # path relative to the repository
    line: int  # the opening fence's line, 1-based
    lang: str  # "bash" or "python"
    ci: str  # run, slow, ros, nightly or skip
    reason: str  # why a block is skipped; a nightly block: the tests that run it in CI
    code: str

    @property
    def where(self) -> str:
        return f"{self.page}:{self.line}"


def extract(page: Path, root: Path = ROOT) -> list[Block]:
    """The runnable blocks of one Markdown page, in order; a bad ``{ci=...}`` raises."""
    lines = page.read_text().splitlines()
    out: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        indent, fence, lang, attrs = m.group(1), m.group(2), m.group(3).lower(), m.group(4)
        j = i + 1
        while j < len(lines) and not lines[j].strip().startswith(fence):
            j += 1
        body = [ln[len(indent) :] if ln.startswith(indent) else ln for ln in lines[i + 1 : j]]
        if lang in RUN_LANGS:
            ci, reason = "run", ""
            if attrs:
                a = _CI.match(attrs)
                where = f"{page.relative_to(root)}:{i + 1}"
                if a is None:
                    raise ValueError(f"{where}: unknown fence attributes {attrs}")
                ci, reason = a.group(1), (a.group(2) or "").strip()
                if ci == "skip" and not reason:
                    raise ValueError(f"{where}: {{ci=skip}} needs a reason: {{ci=skip: why}}")
                if ci == "nightly" and not _TEST_REF.search(reason):
                    raise ValueError(
                        f"{where}: {{ci=nightly}} needs the test that runs its commands in CI: "
                        "{ci=nightly: tests/FILE.py::test_name}"
                    )
            out.append(
                Block(
                    str(page.relative_to(root)),
                    i + 1,
                    RUN_LANGS[lang],
                    ci,
                    reason,
                    "\n".join(body) + "\n",
                )
            )
        i = j + 1
    return out


def pages(root: Path = ROOT) -> list[Path]:
    found = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    return [p for p in found if "data" not in p.relative_to(root).parts[1:2]]


def _ros_available() -> bool:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


def _workdir(tmp: Path) -> Path:
    for name in LINKED:
        (tmp / name).symlink_to(ROOT / name, target_is_directory=True)
    (tmp / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    return tmp


def _env(block: Block, cwd: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["PYTHONPATH"] = os.pathsep.join(
        p for p in (str(ROOT / "src"), env.get("PYTHONPATH", "")) if p
    )
    env.setdefault("AMSFE_GENERATED_DIR", str(ROOT / "generated"))
    env["MPLBACKEND"] = "Agg"
    if block.ci == "ros":
        # a domain of its own, outside tests/test_ros.py's 1..101, and localhost only: two
        # runs on one machine (another checkout, xdist workers) must not hear each other
        env["ROS_DOMAIN_ID"] = str(102 + os.getpid() % 100)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        env.pop("ROS_LOCALHOST_ONLY", None)
        env["ROS_LOG_DIR"] = str(cwd / "ros-log")
    return env


#: One interpreter per page: its python blocks share names, as in a notebook or a session.
_SESSION = r"""
import json, sys, traceback
ns = {"__name__": "__main__"}
for line in sys.stdin:
    try:
        exec(compile(json.loads(line), "<docs block>", "exec"), ns)
        status = "ok"
    except BaseException:
        traceback.print_exc()
        status = "error"
    sys.stderr.flush()
    print("\0amsfe-docs-block " + status, flush=True)
"""


class PageRun:
    """Runs one page's blocks in order in ``cwd``: each bash block a shell of its own, the
    python blocks one interpreter that keeps their names."""

    def __init__(self, cwd: Path) -> None:
        self.cwd = cwd
        self._python: subprocess.Popen[str] | None = None
        self._lines: queue.Queue[str] = queue.Queue()
        self._reader: threading.Thread | None = None

    def run(self, block: Block) -> tuple[bool, str]:
        """Whether the block succeeded, and its output (stdout and stderr)."""
        if block.lang == "bash":
            done = subprocess.run(
                ["bash", "-e", "-c", block.code],
                cwd=self.cwd,
                env=_env(block, self.cwd),
                capture_output=True,
                text=True,
                timeout=BLOCK_TIMEOUT_S,
            )
            return done.returncode == 0, done.stdout + done.stderr
        if self._python is None:
            self._python = subprocess.Popen(
                [sys.executable, "-u", "-c", _SESSION],
                cwd=self.cwd,
                env=_env(block, self.cwd),
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            out = self._python.stdout
            assert out is not None
            self._reader = threading.Thread(
                target=lambda: [self._lines.put(s) for s in out], daemon=True
            )
            self._reader.start()
        assert self._python.stdin is not None
        self._python.stdin.write(json.dumps(block.code) + "\n")
        self._python.stdin.flush()
        output: list[str] = []
        while True:
            try:
                line = self._lines.get(timeout=BLOCK_TIMEOUT_S)
            except queue.Empty:
                return False, "".join(output) + f"\n(no end after {BLOCK_TIMEOUT_S} s)"
            if line.startswith("\0amsfe-docs-block "):
                return line.split()[-1] == "ok", "".join(output)
            output.append(line)

    def close(self) -> None:
        if self._python is not None:
            assert self._python.stdin is not None and self._python.stdout is not None
            self._python.stdin.close()
            self._python.kill()
            self._python.wait()
            if self._reader is not None:
                self._reader.join()  # the pipe's end after the kill; then it can be closed
            self._python.stdout.close()


def run_block(block: Block, cwd: Path) -> tuple[bool, str]:
    """One block alone (a page's blocks: :class:`PageRun`)."""
    page = PageRun(cwd)
    try:
        return page.run(block)
    finally:
        page.close()


def _page_params() -> list[object]:
    params: list[object] = []
    for page in pages():
        blocks = extract(page)
        runnable = [b for b in blocks if b.ci != "skip"]
        if not runnable:
            continue
        rel = str(page.relative_to(ROOT))
        marks = []
        if all(b.ci == "nightly" for b in runnable):
            marks.append(pytest.mark.nightly(f"{rel}: each block's commands run by a test"))
        if any(b.ci == "slow" for b in runnable):
            marks.append(pytest.mark.slow)
        if any(b.ci == "ros" for b in runnable):
            marks.append(pytest.mark.ros)
        params.append(pytest.param(rel, marks=marks, id=rel))
    return params


def _skipped() -> list[object]:
    return [pytest.param(b, id=b.where) for p in pages() for b in extract(p) if b.ci == "skip"]


@pytest.mark.parametrize("page", _page_params())
def test_the_page_s_blocks_run(page: str, tmp_path: Path, pytestconfig: pytest.Config) -> None:
    run = PageRun(_workdir(tmp_path))
    ros = _ros_available()
    nightly = pytestconfig.getoption("--nightly")
    try:
        for block in extract(ROOT / page):
            if block.ci == "skip" or (block.ci == "ros" and not ros):
                continue
            if block.ci == "nightly" and not nightly:
                continue
            ok, output = run.run(block)
            assert ok, f"{block.where} failed\n--- block\n{block.code}--- output\n{output[-5000:]}"
    finally:
        run.close()


@pytest.mark.parametrize("block", _skipped())
def test_a_skipped_block_says_why(block: Block) -> None:
    pytest.skip(f"{block.where}: {block.reason}")


def test_every_page_s_fences_parse() -> None:
    """A ``{ci=skip}`` without its reason, or an unknown attribute, fails here."""
    blocks = [b for p in pages() for b in extract(p)]
    assert any(b.page == "README.md" for b in blocks)
    assert any(b.page.startswith("docs/tutorials/") and b.ci != "skip" for b in blocks)


def test_a_failing_block_is_found_and_a_bad_fence_refused(tmp_path: Path) -> None:
    (tmp_path / "docs").mkdir()
    page = tmp_path / "docs" / "p.md"
    page.write_text(
        "# p\n\n```bash\necho ok > out.txt\n```\n\n```text\nnot run\n```\n\n"
        "```python {ci=slow}\nimport pathlib\nassert pathlib.Path('out.txt').read_text() == 'x'\n"
        "```\n\n```bash {ci=skip: needs a robot}\nexit 3\n```\n"
    )
    blocks = extract(page, tmp_path)
    assert [(b.lang, b.ci, b.line) for b in blocks] == [
        ("bash", "run", 3),
        ("python", "slow", 11),
        ("bash", "skip", 16),
    ]
    assert blocks[2].reason == "needs a robot"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    assert run_block(blocks[0], cwd)[0]
    assert (cwd / "out.txt").read_text() == "ok\n"
    ok, output = run_block(blocks[1], cwd)
    assert not ok and "AssertionError" in output
    page.write_text("```bash {ci=skip}\nexit 3\n```\n")
    with pytest.raises(ValueError, match="needs a reason"):
        extract(page, tmp_path)
    page.write_text("```bash {ci=maybe}\nexit 3\n```\n")
    with pytest.raises(ValueError, match="unknown fence attributes"):
        extract(page, tmp_path)
    shutil.rmtree(cwd)


def test_a_nightly_block_names_a_test_that_exists(tmp_path: Path) -> None:
    """A ``{ci=nightly: ...}`` block (not run in CI) names the test that runs its commands
    in CI: without one it is refused; every name the docs give is a test of this suite."""
    page = tmp_path / "p.md"
    page.write_text("```bash {ci=nightly: the same as a test}\nexit 3\n```\n")
    with pytest.raises(ValueError, match="needs the test that runs its commands"):
        extract(page, tmp_path)
    page.write_text("```bash {ci=nightly: tests/test_x.py::test_y}\nexit 3\n```\n")
    assert [b.ci for b in extract(page, tmp_path)] == ["nightly"]
    missing = []
    for b in (b for p in pages() for b in extract(p) if b.ci == "nightly"):
        for ref in _TEST_REF.findall(b.reason):
            file, name = ref.split("::")
            path = ROOT / file
            if not path.is_file() or not re.search(rf"^def {name}\(", path.read_text(), re.M):
                missing.append(f"{b.where}: {ref}")
    assert not missing, "\n".join(missing)


def test_a_page_s_python_blocks_share_one_session(tmp_path: Path) -> None:
    """As a reader runs them: a name set by one block is there in the next; a failing block
    is reported and the session goes on."""
    page = tmp_path / "p.md"
    page.write_text(
        "```python\nx = 41\nprint('set')\n```\n\n```bash\necho between\n```\n\n"
        "```python\nraise ValueError(f'x is {x}')\n```\n\n```python\nprint(x + 1)\n```\n"
    )
    first, shell, failing, last = extract(page, tmp_path)
    run = PageRun(tmp_path)
    try:
        assert run.run(first) == (True, "set\n")
        assert run.run(shell) == (True, "between\n")
        ok, output = run.run(failing)
        assert not ok and "ValueError: x is 41" in output
        assert run.run(last) == (True, "42\n")
    finally:
        run.close()


#: Pages other branches write (merged with them): named by their code before they land here.
ARRIVING = {
    "docs/api.md",
    "docs/live-control.md",
    "docs/watchdogs.md",
    "docs/live-load.md",
    "docs/camera.md",
    "docs/calibrate.md",
    "docs/input-rules.md",
}


def test_every_docs_page_the_code_names_exists() -> None:
    """Error messages, help texts and docstrings point readers at docs pages; a page moved
    or renamed without them (or a branch merged that still names the old place) fails here."""
    named = re.compile(r"docs/[\w/.-]+?\.md\b")
    missing = []
    for folder in ("src", "tests", "tools"):
        for f in sorted((ROOT / folder).rglob("*.py")):
            for m in named.finditer(f.read_text()):
                target = m.group(0)
                if target in ARRIVING or f.name == "moved_docs_paths.py":  # old paths on purpose
                    continue
                if not (ROOT / target).exists() and f.name != Path(__file__).name:
                    missing.append(f"{f.relative_to(ROOT)}: {target}")
    assert not missing, "\n".join(missing)


def _low_level_modules() -> set[str]:
    """The modules of the low-level API that ``amsfe_sym.api``'s docstring lists (what the
    public names are made of); the docs' examples may use them beside ``amsfe_sym``."""
    import amsfe_sym.api

    names = re.findall(r"`~?(amsfe_sym(?:\.\w+)+)`", amsfe_sym.api.__doc__ or "")
    return {n.rsplit(".", 1)[0] for n in names}


def test_the_docs_examples_import_only_the_public_api() -> None:
    allowed = {"amsfe_sym", "amsfe_sym.api"} | _low_level_modules()
    imports = re.compile(
        r"^\s*(?:from\s+(amsfe_sym[\w.]*)\s+import|import\s+(amsfe_sym[\w.]*))", re.M
    )
    outside = [
        f"{b.where}: {mod}"
        for p in pages()
        for b in extract(p)
        if b.lang == "python"
        for m in imports.finditer(b.code)
        if (mod := m.group(1) or m.group(2)) not in allowed
    ]
    assert "amsfe_sym.sim.loop" in allowed  # the docstring's list was read
    assert not outside, "\n".join(outside)


def test_the_readme_s_links_lead_somewhere() -> None:
    """README.md is outside the site (mkdocs checks the pages' links): its relative links and
    their anchors are checked here, anchors as the site makes them from the headings."""
    toc = pytest.importorskip("markdown.extensions.toc", reason="the [docs] extra (.ci/run)")
    slugify = toc.slugify

    text = (ROOT / "README.md").read_text()
    broken = []
    for target, anchor in re.findall(r"\]\(([^)#\s]+)(?:#([^)\s]+))?\)", text):
        if re.match(r"[a-z]+:", target):
            continue
        path = ROOT / target
        if not path.exists():
            broken.append(target)
        elif anchor and path.suffix == ".md":
            heads = re.findall(r"^#+\s+(.*)$", path.read_text(), re.M)
            if anchor not in {slugify(h, "-") for h in heads}:
                broken.append(f"{target}#{anchor}")
    assert not broken, broken
