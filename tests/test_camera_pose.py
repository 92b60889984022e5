"""The camera's full pose in robot.toml (issue 35, item 4): ``[camera] orientation`` (a unit
quaternion [qx, qy, qz, qw], world-from-camera) beside ``position``, as an alternative to
``look_at`` / ``up``; refused with one line when both are given or it is not a rotation."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from amsfe_sym.codegen import generate
from amsfe_sym.errors import SpecError
from amsfe_sym.load import load_robot
from amsfe_sym.load.rotation import matrix_to_quaternion, quaternion_to_matrix
from amsfe_sym.load.spec import load_spec, robots_dir
from amsfe_sym.runtime.library import ModelLibrary

#: An oblique camera: not along a world axis, up not perpendicular to the optical axis.
POSITION = [0.7, -1.3, 0.45]
LOOK_AT = [0.1, 0.05, -0.2]
UP = [0.1, 0.2, 1.0]


def _robot(folder: Path, camera: str, name: str = "pose_2link") -> Path:
    """paper_2link in ``folder`` with its ``[camera]`` pose lines replaced by ``camera``."""
    folder.mkdir(parents=True, exist_ok=True)
    src = robots_dir() / "paper_2link"
    shutil.copy(src / "paper_2link.urdf", folder)
    lines = []
    for line in (src / "robot.toml").read_text().splitlines():
        key = line.split("=")[0].strip()
        if key in ("position", "look_at", "up"):
            continue
        if line.startswith('name = "paper_2link"'):
            line = f'name = "{name}"'
        lines.append(line)
        if line.startswith("[camera]"):
            lines.append(camera)
    path = folder / "robot.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _look_at_camera() -> str:
    return f"position = {POSITION}\nlook_at = {LOOK_AT}\nup = {UP}"


def _quaternion_camera(q: np.ndarray) -> str:
    return f"position = {POSITION}\norientation = [{', '.join(repr(float(v)) for v in q)}]"


def test_quaternion_round_trip() -> None:
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.standard_normal(4)
        q /= np.linalg.norm(q)
        R = quaternion_to_matrix(q)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
        back = matrix_to_quaternion(R)
        np.testing.assert_allclose(back, q if q[3] >= 0 else -q, atol=1e-14)
    # against scipy's (scalar-last, Hamilton) convention
    from scipy.spatial.transform import Rotation

    q = np.array([0.1, -0.5, 0.3, 0.8])
    q /= np.linalg.norm(q)
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(q).as_matrix(), 1e-15)


def test_look_at_and_quaternion_give_the_same_camera(tmp_path: Path) -> None:
    """The pose as look_at / up and as the equivalent quaternion: the same R_cw and the same
    generated camera map and jacobian, to 1e-12."""
    a = load_robot(_robot(tmp_path / "a", _look_at_camera()))
    q = matrix_to_quaternion(a.camera.R_cw.T)
    b = load_robot(_robot(tmp_path / "b", _quaternion_camera(q)))
    np.testing.assert_allclose(b.camera.R_cw, a.camera.R_cw, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(b.camera.position, a.camera.position)
    np.testing.assert_array_equal(b.camera.K, a.camera.K)
    # the camera axes: z along look_at - position, x perpendicular to up
    z = np.subtract(LOOK_AT, POSITION)
    np.testing.assert_allclose(b.camera.R_cw[2], z / np.linalg.norm(z), atol=1e-12)
    assert abs(b.camera.R_cw[0] @ np.array(UP)) < 1e-12

    libs = []
    for sub in ("a", "b"):
        res = generate(tmp_path / sub / "robot.toml", out=tmp_path / f"gen_{sub}", parts=["model"])
        libs.append(ModelLibrary(res.out_dir))
    assert libs[0].manifest.content_hash != libs[1].manifest.content_hash
    cam = [lib.function("camera") for lib in libs]
    jac = [lib.function("camera_jacobian") for lib in libs]
    rng = np.random.default_rng(11)
    th = np.array([0.15])
    for _ in range(50):
        qv = rng.uniform(-np.pi, np.pi, 2)
        ya, yb = cam[0](qv, th)[0], cam[1](qv, th)[0]
        np.testing.assert_allclose(yb, ya, rtol=0, atol=1e-12 * max(1.0, np.abs(ya).max()))
        np.testing.assert_allclose(yb, a.camera.project(_tip(a, qv)), rtol=1e-12, atol=1e-9)
        Ja, Jb = jac[0](qv, th)[0], jac[1](qv, th)[0]
        np.testing.assert_allclose(Jb, Ja, rtol=0, atol=1e-12 * max(1.0, np.abs(Ja).max()))


def _tip(robot: object, q: np.ndarray) -> np.ndarray:
    """Pinocchio's world position [m] of the tracked point at link angles ``q``."""
    import pinocchio as pin

    model = robot.model  # type: ignore[attr-defined]
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.to_pin_q(q))  # type: ignore[attr-defined]
    return np.asarray(data.oMf[robot.tracked_frame_id].act(robot.tracked_offset))  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("camera", "words"),
    [
        (
            "position = [0, -1.5, 0]\nlook_at = [0, 0, 0]\norientation = [0, 0, 0, 1]",
            ["orientation and look_at"],
        ),
        ("position = [0, -1.5, 0]\nup = [0, 0, 1]\norientation = [0, 0, 0, 1]", ["and up"]),
        ("position = [0, -1.5, 0]\norientation = [0, 0, 0.1, 1]", ["unit quaternion", "norm"]),
        ("position = [0, -1.5, 0]\norientation = [0, 0, 1]", ["4 numbers"]),
        ("orientation = [0, 0, 0, 1]", ["position"]),
        ("position = [0, -1.5, 0]\norientation = [0, 0, 'x', 1]", ["orientation"]),
    ],
)
def test_bad_orientation_is_one_line(tmp_path: Path, camera: str, words: list[str]) -> None:
    _assert_refused(_robot(tmp_path, camera), ["orientation", *words])


def _assert_refused(path: Path, words: list[str]) -> None:
    """Loading ``path`` is refused in one line that holds each of ``words``."""
    with pytest.raises(SpecError) as err:
        load_spec(path)
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg


def test_orientation_is_normalised_and_hashed(tmp_path: Path) -> None:
    q = np.array([0.2, -0.1, 0.4, 0.9])
    q /= np.linalg.norm(q)
    nearly = q * (1 + 5e-7)  # within the tolerance: accepted and normalised
    spec = load_spec(_robot(tmp_path / "a", _quaternion_camera(nearly)))
    assert spec.camera.orientation is not None
    assert np.linalg.norm(spec.camera.orientation) == pytest.approx(1.0, abs=1e-15)
    other = load_spec(_robot(tmp_path / "b", _quaternion_camera(q[[1, 0, 2, 3]])))
    assert spec.fingerprint() != other.fingerprint()


def _with_tracked(path: Path, lines: str) -> Path:
    """``path``'s robot.toml with ``lines`` added under its ``[tracked]`` table."""
    text = path.read_text()
    assert "[tracked]" in text
    path.write_text(text.replace("[tracked]", "[tracked]\n" + lines, 1))
    return path


def test_marker_orientation_is_read_and_normalised(tmp_path: Path) -> None:
    """``[tracked] orientation`` (the marker's frame on its link) is read and normalised."""
    base = load_spec(_robot(tmp_path / "a", _look_at_camera()))
    assert base.tracked.orientation is None
    q = np.array([0.3, -0.2, 0.1, 0.9])
    q /= np.linalg.norm(q)
    line = f"orientation = [{', '.join(repr(float(v)) for v in q * (1 + 5e-7))}]"
    spec = load_spec(_with_tracked(_robot(tmp_path / "b", _look_at_camera()), line))
    assert spec.tracked.orientation is not None
    np.testing.assert_allclose(spec.tracked.orientation, q, atol=1e-15)


@pytest.mark.parametrize(
    ("line", "words"),
    [("orientation = [0, 0, 0.1, 1]", ["unit quaternion"]), ("orientation = 3", ["4 numbers"])],
)
def test_bad_marker_orientation_is_one_line(tmp_path: Path, line: str, words: list[str]) -> None:
    path = _with_tracked(_robot(tmp_path, _look_at_camera()), line)
    _assert_refused(path, ["[tracked] orientation", *words])
