"""The generation cache trusts only what it verified (issue 10, deliverable 2).

Each test has the 1-link arm's build in its own temporary folder: a copy of the one build of
the session (tests/conftest.py's ``paper_1link_build``, with its object cache: a rebuild
links and compiles nothing again).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest

from amsfe_sym.codegen import clean_stale_tmp, generate
from amsfe_sym.errors import CodegenError
from amsfe_sym.runtime.library import ModelLibrary, file_sha256
from tests.conftest import copy_build

ROBOT = "paper_1link"


@pytest.fixture()
def built(tmp_path: Path, paper_1link_build: Path) -> Path:
    """A build of the 1-link arm of this test's own (a copy of the session's); returns its
    ``generated/<name>/`` folder."""
    return copy_build(paper_1link_build, tmp_path) / ROBOT


def _overwrite(path: Path, data: bytes) -> None:
    """Replace a file by a new one (a new inode): the old library may still be mapped in
    this process (generate loads it once), and rewriting a mapped file in place would crash
    the test process itself with SIGBUS."""
    tmp = path.with_name(path.name + ".damaged")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _lib(out_dir: Path) -> Path:
    return out_dir / json.loads((out_dir / "manifest.json").read_text())["library"]


def test_manifest_records_the_library_hash(built: Path) -> None:
    manifest = json.loads((built / "manifest.json").read_text())
    assert manifest["library_sha256"] == file_sha256(_lib(built))
    assert generate(ROBOT, out=built.parent).reused


def test_truncated_library_is_rebuilt_not_reused(built: Path) -> None:
    lib = _lib(built)
    good = lib.read_bytes()
    _overwrite(lib, good[:100])
    res = generate(ROBOT, out=built.parent)
    assert not res.reused
    assert len(lib.read_bytes()) == len(good)
    assert file_sha256(lib) == json.loads((built / "manifest.json").read_text())["library_sha256"]
    ModelLibrary(built).function("transition")  # loads and binds


@pytest.mark.parametrize("damage", ["truncate", "flip"])
def test_runtime_refuses_a_damaged_library(built: Path, damage: str) -> None:
    lib = _lib(built)
    data = bytearray(lib.read_bytes())
    if damage == "truncate":
        data = data[:100]
    else:  # same size, flipped bytes in the middle (used to segfault in check/simulate)
        mid = len(data) // 2
        for i in range(mid, mid + 64):
            data[i] ^= 0xFF
    _overwrite(lib, bytes(data))
    with pytest.raises(CodegenError, match="sha256") as info:
        ModelLibrary(built)
    assert "\n" not in str(info.value)
    assert "amsfe generate --force" in str(info.value)


def test_manifest_without_hash_is_refused(built: Path) -> None:
    mpath = built / "manifest.json"
    manifest = json.loads(mpath.read_text())
    del manifest["library_sha256"]
    mpath.write_text(json.dumps(manifest))
    with pytest.raises(CodegenError, match="without library_sha256"):
        ModelLibrary(built)
    assert not generate(ROBOT, out=built.parent).reused  # and generate rebuilds it


def test_stale_temporary_folders_are_cleaned(tmp_path: Path, paper_1link_build: Path) -> None:
    """Only a build folder this tool marked, whose process is gone, is removed; an unmarked
    look-alike (a user's folder), a running build and another robot's name are kept."""
    from amsfe_sym.core.folders import TMP_MARKER, make_tmp

    dead = tmp_path / f".{ROBOT}-99999999-abc"  # a killed build: marked, no such pid
    dead.mkdir()
    (dead / TMP_MARKER).write_text("amsfe_sym temporary folder; pid 99999999; start 1\n")
    unmarked = tmp_path / f".{ROBOT}-99999999-notes"  # a user's look-alike: no marker
    live = make_tmp(tmp_path, f".{ROBOT}-{os.getpid()}-")  # a build in progress: kept
    other = tmp_path / f".{ROBOT}-extra-1-x"  # another robot's name ('paper_1link-extra')
    for d in (unmarked, other):
        d.mkdir()
    hour_ago = time.time() - 7200
    os.utime(live, (hour_ago, hour_ago))  # an age alone never removes a live build
    removed = clean_stale_tmp(tmp_path, ROBOT)
    assert removed == [dead]
    assert live.is_dir() and other.is_dir() and unmarked.is_dir()
    copy_build(paper_1link_build, tmp_path, objects_only=True)  # (compiled objects: a link)
    generate(ROBOT, out=tmp_path)
    kept = [ROBOT, live.name, other.name, unmarked.name, ".objects"]  # .objects: compile_units
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(kept)
    assert not (tmp_path / ROBOT / TMP_MARKER).exists()


def test_native_flags_put_the_cpu_kind_in_the_cache_key() -> None:
    """-march=native ties a library to the CPU: the key then holds the CPU kind, so a cache
    built on another CPU is not reused; without it the key is unchanged (no "cpu" entry)."""
    from amsfe_sym.codegen.cache import compiler, content_hash, cpu_kind
    from amsfe_sym.load.spec import find_robot, load_spec

    spec = load_spec(find_robot("paper_2link"))
    plain_key, plain = content_hash(spec, ["-O1", "-fPIC", "-shared"])
    native_key, native = content_hash(spec, ["-O1", "-march=native", "-fPIC", "-shared"])
    assert "cpu" not in plain and cpu_kind(compiler(), ["-O1"]) is None
    assert native["cpu"] == cpu_kind(compiler(), ["-march=native"]) and native["cpu"]
    assert native_key != plain_key


def test_a_robot_of_the_same_name_from_another_source_is_named(built: Path) -> None:
    """The folder is named by the robot's name: the bare URDF of the 1-link arm is also
    ``paper_1link`` but not the shipped robot.toml, so its build would replace the shipped
    one's: generate says whose library it replaces (``_other_source``, read from the real
    manifest of the build)."""
    from amsfe_sym.codegen.build import _other_source
    from amsfe_sym.load.spec import load_spec

    shipped = load_spec(ROBOT)
    assert _other_source(built, shipped) is None
    bare = load_spec(shipped.urdf)
    assert bare.name == ROBOT and bare.spec_path is None
    assert _other_source(built, bare) == str(shipped.spec_path)
    assert _other_source(built.parent / "nothing-here", bare) is None


def test_a_library_reused_by_another_checkout_names_that_checkouts_files(tmp_path: Path) -> None:
    """Two copies of a robot folder (two checkouts) share one library cache: the library is
    built once, and each loads it naming its own URDF and robot.toml, even after the copy
    that built it is deleted (simulate --bag's /tf and the simulated marker read them)."""
    import shutil

    from amsfe_sym.codegen import load_library
    from amsfe_sym.load.spec import robots_dir

    out = tmp_path / "generated"
    a, b = tmp_path / "a" / "paper_1link", tmp_path / "b" / "paper_1link"
    shutil.copytree(robots_dir() / "paper_1link", a)
    shutil.copytree(robots_dir() / "paper_1link", b)
    lib_a = load_library(a / "robot.toml", out=out)
    assert lib_a.manifest.spec == str((a / "robot.toml").resolve())
    shutil.rmtree(tmp_path / "a")
    lib_b = load_library(b / "robot.toml", out=out)
    assert lib_b.dir == lib_a.dir  # the same library, reused
    assert json.loads((lib_b.dir / "manifest.json").read_text())["spec"].startswith(str(a))
    assert lib_b.manifest.spec == str((b / "robot.toml").resolve())
    assert Path(lib_b.manifest.urdf).is_file() and Path(lib_b.manifest.urdf).is_relative_to(b)
