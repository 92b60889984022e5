"""``amsfe calibrate`` end to end on simulated recordings (issue 35, item 5, its done-when):
a "true" calib_arm (the typed camera moved 3 cm and turned 2 deg, the marker 2 cm off the
tip, stamps 25 ms late) simulated by ``amsfe simulate --bag`` (30 s, 1 kHz encoders, a 30 Hz
640x480 camera with 1 px noise, the arm moving), calibrated with the typed robot.toml.

The method was tuned on seed 5 only; these seeds (4242, 4243) were not looked at before the
bounds were written.  tools/calibrate_seeds.py measures the spread over more seeds
(docs/calibrate.md, "Accuracy").
"""

from __future__ import annotations

import json
import math
import re
import shutil
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomllib

from amsfe_sym.apps.cli import main
from amsfe_sym.calibration.spec_out import moved_camera_spec
from amsfe_sym.codegen import generate
from amsfe_sym.load import load_robot
from amsfe_sym.runtime.library import ModelLibrary
from amsfe_sym.topics.spec import TopicSpec, read_topic_spec

pytestmark = pytest.mark.slow

DATA = Path(__file__).parent / "data" / "calibrate"
STAMP_OFFSET = 0.025


@pytest.fixture(scope="module")
def truth(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The true robot.toml, with its libraries in a folder of this module's own: a library
    found in a shared cache keeps the spec path of whoever built it first (its manifest), and
    ``simulate --bag`` reads the spec there (for /tf), which another session's temporary
    folder no longer has."""
    folder = tmp_path_factory.mktemp("true")
    text = moved_camera_spec(
        load_robot(DATA / "robot.toml"), np.random.default_rng(0), name="calib_arm_true"
    )
    (folder / "robot.toml").write_text(text)
    shutil.copy(DATA / "calib-sim.toml", folder)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("AMSFE_GENERATED_DIR", str(folder / "generated"))
        yield folder / "robot.toml"


def _simulate(truth: Path, out: Path, seed: int, *extra: str) -> Path:
    rc = main(
        [
            "simulate",
            str(truth.parent / "calib-sim.toml"),
            "--controller",
            "truth-ct",
            "--out",
            str(out),
            "--bag",
            "--no-plots",
            "--no-progress",
            "--seed",
            str(seed),
            "--set",
            f"camera.stamp_offset={STAMP_OFFSET}",
            *extra,
        ]
    )
    assert rc == 0
    return out / "bag"


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return math.degrees(math.acos(min(1.0, max(-1.0, (np.trace(Ra @ Rb.T) - 1) / 2))))


@pytest.mark.parametrize("seed", [4242, 4243])
def test_calibrate_recovers_the_true_camera(
    truth: Path, tmp_path: Path, seed: int, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _simulate(truth, tmp_path / "run", seed)
    out = tmp_path / "cal"
    capsys.readouterr()
    rc = main(["calibrate", str(bag), "--robot", str(DATA / "robot.toml"), "--out", str(out)])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    for words in (
        "camera position x",
        "marker offset z",
        "time offset",
        "95 % interval (linearised)",
        "reprojection error per frame: median",
        "frames dropped",
        "q = qm - (u - Mm qmdd - Fm qmd) / Ks",
    ):
        assert words in printed
    assert "cannot determine" not in printed

    true, cal = load_robot(truth), load_robot(out / "robot.toml")
    result = json.loads((out / "calibration.json").read_text())
    # the bounds
    assert np.linalg.norm(cal.camera.position - true.camera.position) < 2e-3
    assert _rotation_deg(cal.camera.R_cw, true.camera.R_cw) < 0.1
    assert np.linalg.norm(cal.tracked_offset - true.tracked_offset) < 1e-3
    assert abs(result["time_offset_s"] - STAMP_OFFSET) < 1e-3
    # the truth within 4 of the stated sigmas (the 95 % coverage is measured over seeds)
    p = result["parameters"]
    for k, axis in enumerate("xyz"):
        err = cal.camera.position[k] - true.camera.position[k]
        assert abs(err) < 4 * p[f"camera_{axis}"]["std"]
        err = cal.tracked_offset[k] - true.tracked_offset[k]
        assert abs(err) < 4 * p[f"offset_{axis}"]["std"]
    assert abs(result["time_offset_s"] - STAMP_OFFSET) < 4 * p["time_offset"]["std"]
    assert 0.8 < result["pixel_std"] < 1.2
    # the error model the intervals took, as printed; on white pixel noise the sandwich is
    # about as wide as the white-noise interval it records beside it
    model = result["error_model"]
    assert model["kind"] == "sandwich" and model["description"] in printed
    assert model["bandwidth_frames"] >= 0 and model["shift_sigma_px"] is None
    ratio = [p[k]["std"] / p[k]["std_white"] for k in p if p[k]["fitted"]]
    assert min(ratio) > 0.7 and max(ratio) < 1.4, ratio
    # the time offset as a topic spec key, for amsfe estimate / node (the defaults + the key)
    topics = read_topic_spec(out / "topics.toml")
    assert topics.camera_time_offset == round(result["time_offset_s"], 6)
    assert topics == replace(TopicSpec(), camera_time_offset=topics.camera_time_offset)
    assert f"--log-spec {out / 'topics.toml'}" in printed
    assert (out / "residuals.png").stat().st_size > 10_000
    assert len((out / "residuals.csv").read_text().splitlines()) > 800

    # amsfe generate accepts the calibrated robot.toml; its camera sees what the true one does
    lib_cal = ModelLibrary(
        generate(out / "robot.toml", out=tmp_path / "gen", parts=["model"]).out_dir
    )
    lib_true = ModelLibrary(generate(truth, out=tmp_path / "gen", parts=["model"]).out_dir)
    rng = np.random.default_rng(seed)
    motion = tomllib.loads((DATA / "calib-sim.toml").read_text())["trajectory"]
    centre, reach = np.array(motion["offset"]), np.array(motion["amplitude"])
    for _ in range(50):  # poses within the recorded motion's ranges
        q = rng.uniform(centre - reach, centre + reach)
        y_cal = lib_cal.function("camera")(q, np.zeros(0))[0].reshape(2)
        y_true = lib_true.function("camera")(q, np.zeros(0))[0].reshape(2)
        assert np.linalg.norm(y_cal - y_true) < 1.0


def test_arm_at_rest_cannot_determine_the_time_offset(
    truth: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An arm holding still: one line naming the time offset, exit 2, nothing written."""
    scenario = truth.parent / "calib-sim.toml"
    text = scenario.read_text()
    q0 = tomllib.loads(text)["plant"]["q0"]  # held where the motion starts
    start, end = text.index("[trajectory]"), text.index("[controller_gains")
    rest = text[:start] + f'[trajectory]\nkind = "constant"\nq = {q0}\n\n' + text[end:]
    rest = re.sub(r"\n(qd0?) = \[[^]]*\]", r"\n\1 = [0.0, 0.0, 0.0]", rest)  # at rest from t = 0
    assert tomllib.loads(rest)["plant"]["qd0"] == tomllib.loads(rest)["estimate0"]["qd"] == [0] * 3
    (truth.parent / "rest.toml").write_text(rest)
    rc = main(
        [
            "simulate",
            str(truth.parent / "rest.toml"),
            "--controller",
            "truth-ct",
            "--out",
            str(tmp_path / "run"),
            "--bag",
            "--no-plots",
            "--no-progress",
            "--duration",
            "5",
        ]
    )
    assert rc == 0
    out = tmp_path / "cal"
    capsys.readouterr()
    rc = main(
        [
            "calibrate",
            str(tmp_path / "run" / "bag"),
            "--robot",
            str(DATA / "robot.toml"),
            "--out",
            str(out),
        ]
    )
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1
    assert "time offset cannot be determined" in err and "at rest" in err
    assert not out.exists()


def test_bad_input_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A log that is not there, a robot that is not there, an --out that is the log."""
    robot = str(DATA / "robot.toml")
    cases = [
        ["calibrate", str(tmp_path / "missing.mcap"), "--robot", robot],
        ["calibrate", str(tmp_path), "--robot", str(tmp_path / "nothing.toml")],
        ["calibrate", str(tmp_path), "--robot", robot, "--pixel-std", "0"],
    ]
    for argv in cases:
        capsys.readouterr()
        assert main([*argv, "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and err.startswith("error:"), err
        assert not (tmp_path / "out").exists()


def test_the_time_offset_key_fuses_late_stamps_as_the_true_timing(
    truth: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A recording whose camera stamps are 25 ms late (the simulation's own oosm estimate,
    fed the true exposures, is the reference): ``amsfe estimate`` without ``[camera]
    time_offset`` takes the frames 25 ms late and gates most of them; with the key it fuses
    every frame, its camera NIS in band and its NEES as the reference's."""
    sim = ["--estimator", "oosm", "--duration", "10"]
    bag = _simulate(truth, tmp_path / "run", 4244, *sim)
    ref = json.loads((tmp_path / "run" / "summary.json").read_text())
    key = tmp_path / "topics.toml"
    key.write_text(f"[camera]\ntime_offset = {STAMP_OFFSET}\n")
    got, printed = {}, {}
    for which, extra in (("without", []), ("with", ["--log-spec", str(key)])):
        out = tmp_path / which
        argv = ["estimate", str(bag), "--scenario", str(truth.parent / "calib-sim.toml")]
        capsys.readouterr()
        assert main([*argv, "--estimator", "oosm", "--no-plots", "--out", str(out), *extra]) == 0
        printed[which] = capsys.readouterr().out
        got[which] = json.loads((out / "summary.json").read_text())
    said = "camera: exposures +25.000 ms before the stamps ([camera] time_offset), taken 25 tick"
    assert said in printed["with"] and "[camera] time_offset" not in printed["without"]
    w, wo = got["with"], got["without"]
    frames = w["counters"]["frames_applied"]
    assert frames > 290 and w["counters"]["refused_gated"] == 0
    assert 1.6 < w["nis"]["camera"]["mean"] < 2.5 and w["nis"]["camera"]["inside_95"] > 0.9
    assert wo["counters"]["refused_gated"] > frames / 2
    assert wo["nis"]["camera"]["mean"] > 20
    nees_ref = ref["nees_mean"]
    assert abs(w["nees_mean"] - nees_ref) < 0.05 * nees_ref

    # calibrate measures the offset from the stamps whatever the topic spec says: the key in
    # --log-spec is not applied, and the topics.toml written replaces it
    cal = tmp_path / "cal"
    argv = ["calibrate", str(bag), "--robot", str(DATA / "robot.toml"), "--log-spec", str(key)]
    assert main([*argv, "--out", str(cal), "--no-plots"]) == 0
    written = read_topic_spec(cal / "topics.toml").camera_time_offset
    assert abs(written - STAMP_OFFSET) < 1e-3
