"""codegen/compile_units.py: a library's C files as parallel units, the robot-independent
ones compiled once per content (real gcc on small files, real dlopen of the result)."""

from __future__ import annotations

import ctypes
from pathlib import Path

import pytest

from amsfe_sym.codegen.cache import cflags, compiler
from amsfe_sym.codegen.compile_units import Unit, compile_library

KEY = {"compiler": "test", "cflags": ["-O1"], "machine": "x", "cpu": None}


def _write(folder: Path, shared_body: str) -> list[Unit]:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "robot.c").write_text("int shared_value(void);\nint robot(void) { return 40; }\n")
    (folder / "shared.c").write_text(f"int shared_value(void) {{ {shared_body} }}\n")
    return [Unit("robot.c"), Unit(str(folder / "shared.c"), shared=True)]


def _build(folder: Path, units: list[Unit], cache: Path, capsys, reuse: bool = True) -> str:
    proc = compile_library(
        units, compiler(), cflags(), folder, "libt.so", KEY, cache, True, "t", reuse=reuse
    )
    assert proc.returncode == 0, proc.stderr
    return str(capsys.readouterr().err)


def test_shared_units_are_compiled_once_per_content(tmp_path, capsys) -> None:
    cache = tmp_path / ".objects"
    err = _build(tmp_path / "a", _write(tmp_path / "a", "return 2;"), cache, capsys)
    assert "compiling (2 of 2 unit(s), 0 from the object cache" in err
    assert len(list(cache.glob("shared-*.o"))) == 1
    lib = ctypes.CDLL(str(tmp_path / "a" / "libt.so"))
    assert lib.robot() + lib.shared_value() == 42

    # another library, the same shared source: its object is linked from the cache
    err = _build(tmp_path / "b", _write(tmp_path / "b", "return 2;"), cache, capsys)
    assert "compiling (1 of 2 unit(s), 1 from the object cache" in err
    assert ctypes.CDLL(str(tmp_path / "b" / "libt.so")).shared_value() == 2

    # other bytes, another key: compiled, and both objects are kept
    err = _build(tmp_path / "c", _write(tmp_path / "c", "return 3;"), cache, capsys)
    assert "compiling (2 of 2 unit(s), 0 from the object cache" in err
    assert ctypes.CDLL(str(tmp_path / "c" / "libt.so")).shared_value() == 3
    assert len(list(cache.glob("shared-*.o"))) == 2

    # --force (reuse=False) compiles it again
    err = _build(tmp_path / "d", _write(tmp_path / "d", "return 2;"), cache, capsys, False)
    assert "compiling (2 of 2 unit(s), 0 from the object cache" in err


def test_an_empty_cached_object_is_compiled_again(tmp_path, capsys) -> None:
    cache = tmp_path / ".objects"
    _build(tmp_path / "a", _write(tmp_path / "a", "return 2;"), cache, capsys)
    (obj,) = cache.glob("shared-*.o")
    obj.write_bytes(b"")  # a truncated object (a disk that filled up)
    err = _build(tmp_path / "b", _write(tmp_path / "b", "return 2;"), cache, capsys)
    assert "compiling (2 of 2 unit(s), 0 from the object cache" in err
    assert obj.stat().st_size > 0
    assert ctypes.CDLL(str(tmp_path / "b" / "libt.so")).shared_value() == 2


def test_a_failed_unit_is_the_error_and_nothing_is_cached(tmp_path) -> None:
    units = _write(tmp_path, "return 2;")
    (tmp_path / "robot.c").write_text("int robot(void) { return }\n")
    cache = tmp_path / ".objects"
    proc = compile_library(units, compiler(), cflags(), tmp_path, "libt.so", KEY, cache, False, "t")
    assert proc.returncode != 0 and "robot.c" in proc.stderr
    assert not (tmp_path / "libt.so").exists()
    assert not cache.exists() or not list(cache.glob("*.o"))


@pytest.mark.parametrize("jobs", ["1", "3"])
def test_build_jobs_reads_the_environment(monkeypatch, jobs: str) -> None:
    from amsfe_sym.codegen.compile_units import build_jobs

    monkeypatch.setenv("AMSFE_BUILD_JOBS", jobs)
    assert build_jobs() == int(jobs)
    monkeypatch.delenv("AMSFE_BUILD_JOBS")
    assert build_jobs() >= 1  # unset: the cores


@pytest.mark.parametrize("jobs", ["zero", "abc", "0", "-1", "2.5"])
def test_a_bad_build_jobs_is_refused_not_ignored(monkeypatch, jobs: str) -> None:
    """``$AMSFE_BUILD_JOBS=abc`` was ignored without a word (issue 25): one line now."""
    from amsfe_sym.codegen.compile_units import build_jobs
    from amsfe_sym.errors import CodegenError

    monkeypatch.setenv("AMSFE_BUILD_JOBS", jobs)
    with pytest.raises(CodegenError, match=r"\$AMSFE_BUILD_JOBS.*integer >= 1.*Fix: export"):
        build_jobs()


def test_the_same_model_under_another_name_links_the_first_one_s_object(tmp_path, capsys) -> None:
    """The generated C has one symbol prefix for every robot (``GENERATED_PREFIX``), so a
    model renamed (a sweep's derived spec, the tutorial's copy of the UR5) is the same
    bytes: its object comes from the cache, and the two libraries compute the same."""
    from dataclasses import replace

    import numpy as np

    from amsfe_sym.codegen import generate
    from amsfe_sym.load.spec import load_spec
    from amsfe_sym.runtime.library import ModelLibrary

    spec = load_spec("paper_1link")
    first = generate(replace(spec, name="one"), out=tmp_path, parts=("model",), progress=True)
    assert "compiling (1 of 1 unit(s), 0 from the object cache" in capsys.readouterr().err
    second = generate(replace(spec, name="two"), out=tmp_path, parts=("model",), progress=True)
    assert "compiling (0 of 1 unit(s), 1 from the object cache" in capsys.readouterr().err
    assert not second.reused and second.out_dir.name == "two-model"
    assert (first.out_dir / "one.c").read_bytes() == (second.out_dir / "two.c").read_bytes()
    a, b = ModelLibrary(first.out_dir), ModelLibrary(second.out_dir)
    x, u = np.linspace(0.1, 0.4, a.N), np.array([0.3])
    np.testing.assert_array_equal(a.function("transition")(x, u), b.function("transition")(x, u))
    # another model (another T): another object
    other = replace(spec, name="three", model=replace(spec.model, T=spec.model.T / 2))
    generate(other, out=tmp_path, parts=("model",), progress=True)
    assert "compiling (1 of 1 unit(s), 0 from the object cache" in capsys.readouterr().err
    assert len(list((tmp_path / ".objects").glob("generated-*.o"))) == 2


def test_objects_unused_for_a_month_are_removed(tmp_path) -> None:
    import os
    import time

    from amsfe_sym.codegen.compile_units import OBJECT_MAX_AGE_S, _prune

    old, new = tmp_path / "old.o", tmp_path / "new.o"
    for f in (old, new):
        f.write_bytes(b"x")
    t = time.time() - OBJECT_MAX_AGE_S - 60
    os.utime(old, (t, t))
    _prune(tmp_path)
    assert not old.exists() and new.exists()
