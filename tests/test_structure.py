"""The interfaces issue 7 introduced: the typed manifest, the one camera-timing resolver
(None = the robot's, a delay of 0 allowed), ``--set`` on ``simulate``, provenance."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.apps.cli import main
from amsfe_sym.codegen import library_for
from amsfe_sym.errors import CodegenError, ConfigError
from amsfe_sym.runtime.manifest import Manifest
from amsfe_sym.scenario import apply_sets, camera_timing, load_scenario
from amsfe_sym.sim.builders import build_run
from amsfe_sym.sim.loop import run


@pytest.fixture(scope="module")
def paper_exp():
    sc = load_scenario("paper-exp")
    return sc, library_for(sc)


def test_manifest_fields_match_the_document(paper_exp) -> None:
    _, lib = paper_exp
    m, raw = lib.manifest, lib.manifest.raw
    assert (m.n, m.p, m.N, m.T) == (raw["n"], raw["p"], raw["N"], raw["T"])
    assert (m.camera.period, m.camera.delay) == (raw["camera"]["period"], raw["camera"]["delay"])
    assert [t.name for t in m.theta] == [t["name"] for t in raw["theta"]]
    assert list(m.actuators.Ks) == raw["actuators"]["Ks"]
    sig = m.functions["camera_measure"]
    assert [o.name for o in sig.outputs] == ["y", "dy_dq", "depth"]
    assert sig.outputs[1].matrix and sig.outputs[1].np_shape == (2, m.n)
    broken = {k: v for k, v in raw.items() if k != "camera"}
    with pytest.raises(CodegenError, match="camera"):
        Manifest.from_dict(broken)


def test_camera_timing_none_is_the_robots_and_zero_is_zero(paper_exp) -> None:
    sc, lib = paper_exp
    l, d = lib.manifest.camera.period, lib.manifest.camera.delay
    assert sc.camera.period is None and sc.camera.delay is None
    t = camera_timing(sc, l, d)
    assert (t.period, t.delay, t.max_delay) == (l, d, d + sc.camera.jitter_steps)
    now = dataclasses.replace(sc, camera=dataclasses.replace(sc.camera, delay=0))
    assert camera_timing(now, l, d).delay == 0
    assert apply_sets(sc, ["camera.delay=0"]).camera.delay == 0
    assert apply_sets(now, ["camera.delay=robot"]).camera.delay is None
    with pytest.raises(ConfigError, match="phase"):
        camera_timing(apply_sets(sc, ["camera.phase=7"]), 4, 4)


def test_a_zero_delay_camera_delivers_at_exposure(paper_exp) -> None:
    sc, lib = paper_exp
    sc = apply_sets(sc, ["camera.delay=0", "duration=0.3"]).with_overrides(estimator="naive")
    res = run(sc, lib)
    assert res.frames.shape[0] > 0
    assert np.array_equal(res.frames[:, 0], res.frames[:, 1])  # exposure step == delivery step
    parts = build_run(sc, lib)
    assert parts.estimator.config.camera_max_delay == 0 and parts.timing.delay == 0


def test_old_zero_period_and_bad_sentinels_are_refused(tmp_path: Path) -> None:
    src = (Path(load_scenario("paper-exp").source or "")).read_text()
    for line, needle in (("period = 0", "old way"), ('delay = "late"', "robot")):
        path = tmp_path / "old.toml"
        path.write_text(src.replace("[camera]\n", f"[camera]\n{line}\n"))
        with pytest.raises(ConfigError, match=needle):
            load_scenario(path)
    path.write_text(src.replace("[camera]\n", '[camera]\ndelay = "robot"\n'))
    assert load_scenario(path).camera.delay is None


def test_a_short_buffer_is_refused_before_anything_is_generated(tmp_path: Path) -> None:
    sc = apply_sets(load_scenario("paper-sim"), ["filter.buffer_steps=10"])
    with pytest.raises(ConfigError, match="buffer_steps"):
        library_for(sc.with_overrides(estimator="oosm"), out=tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_simulate_takes_set_and_records_provenance(tmp_path: Path, capsys) -> None:
    out = tmp_path / "run"
    argv = ["simulate", "paper-exp", "--controller", "amsfe", "--duration", "0.2", "--no-plots"]
    argv += ["--no-progress"]
    assert main([*argv, "--set", "camera.delay=0", "--out", str(out)]) == 0
    assert "delay = 0" in (out / "config.toml").read_text()
    prov = json.loads((out / "summary.json").read_text())["provenance"]
    for key in ("commit", "dirty", "machine", "python", "numpy", "casadi", "pinocchio"):
        assert key in prov
    assert main([*argv, "--set", "camera.nope=1", "--out", str(out)]) == 2
    assert "camera.nope" in capsys.readouterr().err
