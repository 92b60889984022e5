"""The Franka Emika Panda of robots/panda/: write its URDF, and measure every number its
README and robot.toml quote.

    .venv/bin/python tools/panda_model.py urdf    # robots/panda/panda.urdf from example-robot-data
    .venv/bin/python tools/panda_model.py check   # the checks, printed (and docs/data/panda.json)

``urdf`` copies example-robot-data's ``panda_description/urdf/panda.urdf`` (franka_ros'
``franka_description``, Apache-2.0) and drops only its ``<visual>`` and ``<collision>``
elements (meshes the toolkit never reads); every joint, link, origin, axis, limit and inertial
element is kept as it is.

``check`` measures, with Pinocchio on the shipped files:
- the URDF's flange frame (``panda_link8``) against the product of Franka's published
  modified Denavit-Hartenberg transforms (Craig's convention);
- the URDF's inertial parameters of links 1-7 against the identified ones of Gaz et al.
  (RA-L 2019, Supplementary Material tables VIII and IX, as the authors' repository
  marcocognetti/FrankaEmikaPandaDynModel lists them), and that the one difference (link 1's
  centre-of-mass z) changes neither M(q) nor the bias;
- the zero-velocity slope of Gaz et al.'s identified friction model (the Fm choice);
- the flexible-joint modes w T of robot.toml's Ks, Mm over random q (w^2 = Ks (1/J + 1/Mm));
- M's smallest eigenvalue, and where the tracked point lands in the image.
"""

from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PANDA = ROOT / "robots" / "panda"

#: Franka's modified DH table (Craig): (a_{i-1}, d_i, alpha_{i-1}) for joints 1..7 and the
#: flange (joint 8, fixed at theta = 0) [m, rad].
FRANKA_DH = (
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -np.pi / 2),
    (0.0, 0.316, np.pi / 2),
    (0.0825, 0.0, np.pi / 2),
    (-0.0825, 0.384, -np.pi / 2),
    (0.0, 0.0, np.pi / 2),
    (0.088, 0.0, np.pi / 2),
    (0.0, 0.107, 0.0),
)


def gaz2019() -> dict[str, list]:
    """Gaz et al. 2019's identified parameters (robots/panda/gaz2019.toml, with its source)."""
    import tomllib

    with (PANDA / "gaz2019.toml").open("rb") as fh:
        return tomllib.load(fh)


def erd_panda_urdf() -> Path:
    """example-robot-data's panda.urdf (installed with the ``example-robot-data`` package)."""
    from importlib import metadata

    dist = metadata.distribution("example-robot-data")
    base = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")))
    return base / "panda_description" / "urdf" / "panda.urdf"


def write_urdf() -> Path:
    """robots/panda/panda.urdf: example-robot-data's file without visual/collision elements."""
    src = erd_panda_urdf()
    tree = ET.parse(src)
    root = tree.getroot()
    for link in root.findall("link"):
        for tag in ("visual", "collision"):
            for el in link.findall(tag):
                link.remove(el)
    ET.indent(tree, space="  ")
    body = ET.tostring(root, encoding="unicode")
    header = (
        '<?xml version="1.0" ?>\n'
        "<!-- Franka Emika Panda: example-robot-data 6.0.0's panda_description/urdf/panda.urdf\n"
        "     (upstream franka_ros/franka_description, Apache-2.0, see LICENSE-franka_description),\n"  # noqa: E501 (the shipped URDF's bytes)
        "     with its <visual> and <collision> elements removed by tools/panda_model.py urdf.\n"
        "     Kinematics: Franka's modified DH parameters.  Inertial parameters of links 1-7:\n"
        "     Gaz et al., RA-L 2019 (see README.md).  Hand and fingers: franka_description's. -->\n"
    )
    out = PANDA / "panda.urdf"
    out.write_text(header + body + "\n")
    return out


def _dh(a: float, d: float, alpha: float, theta: float) -> np.ndarray:
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -d * sa],
            [st * sa, ct * sa, ca, d * ca],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def check() -> dict[str, object]:
    """Every measured number of robots/panda/README.md (printed and returned)."""
    import pinocchio as pin

    from amsfe_sym.load import load_robot
    from amsfe_sym.load.spec import load_spec

    out: dict[str, object] = {}
    gz = gaz2019()
    GAZ_MASS, GAZ_COM, GAZ_INERTIA = gz["mass"], gz["com"], gz["inertia"]
    spec = load_spec(PANDA / "robot.toml")
    full = pin.buildModelFromUrdf(str(PANDA / "panda.urdf"))
    data = full.createData()
    rng = np.random.default_rng(0)
    lo, hi = full.lowerPositionLimit, full.upperPositionLimit
    fid = full.getFrameId("panda_link8")
    err_p = err_r = 0.0
    for _ in range(20):
        q = rng.uniform(lo, hi)
        pin.framesForwardKinematics(full, data, q)
        T = np.eye(4)
        for i, (a, d, al) in enumerate(FRANKA_DH):
            T = T @ _dh(a, d, al, q[i] if i < 7 else 0.0)
        M = data.oMf[fid]
        err_p = max(err_p, float(np.max(np.abs(M.translation - T[:3, 3]))))
        err_r = max(err_r, float(np.max(np.abs(M.rotation - T[:3, :3]))))
    out["flange_vs_dh"] = {"position_m": err_p, "rotation": err_r, "samples": 20}

    # inertial parameters of links 1-7 against Gaz et al.
    diffs = {"mass": 0.0, "com": 0.0, "inertia": 0.0}
    com_differs = []
    root = ET.parse(PANDA / "panda.urdf").getroot()
    links = {ln.get("name"): ln for ln in root.findall("link")}
    for i in range(7):
        inert = links[f"panda_link{i + 1}"].find("inertial")
        assert inert is not None
        m = float(inert.find("mass").get("value"))  # type: ignore[union-attr]
        c = np.array(inert.find("origin").get("xyz").split(), float)  # type: ignore[union-attr]
        t = inert.find("inertia")
        assert t is not None
        inertia = [float(t.get(k)) for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")]
        diffs["mass"] = max(diffs["mass"], abs(m - GAZ_MASS[i]))
        diffs["inertia"] = max(
            diffs["inertia"], float(np.max(np.abs(np.subtract(inertia, GAZ_INERTIA[i]))))
        )
        dc = np.abs(c - np.array(GAZ_COM[i]))
        if np.max(dc) > 0:
            com_differs.append({"link": i + 1, "urdf": c.tolist(), "gaz": list(GAZ_COM[i])})
        diffs["com"] = max(diffs["com"], float(np.max(dc)) if i else float(np.max(dc[:2])))
    out["urdf_vs_gaz_max_abs"] = diffs
    out["urdf_vs_gaz_com_differs"] = com_differs
    # link 1's centre-of-mass z: does it enter M or the bias?  (fingers at 0, as locked)
    gaz = full.copy()
    iner = gaz.inertias[1]
    lever = iner.lever.copy()
    lever[2] = GAZ_COM[0][2]
    gaz.inertias[1] = pin.Inertia(iner.mass, lever, iner.inertia)
    gdata = gaz.createData()
    dM = db = 0.0
    for _ in range(50):
        q = rng.uniform(lo, hi)
        q[7:] = 0.0
        v = rng.uniform(-2.0, 2.0, full.nv)
        v[7:] = 0.0
        dM = max(dM, float(np.max(np.abs(pin.crba(full, data, q) - pin.crba(gaz, gdata, q)))))
        db = max(db, float(np.max(np.abs(pin.nle(full, data, q, v) - pin.nle(gaz, gdata, q, v)))))
    out["link1_com_z_effect"] = {"M": dM, "bias": db, "samples": 50}

    # friction: zero-velocity slope of the identified sigmoid [N m s/rad], torque at 1 rad/s
    slopes, at1 = [], []
    for p1, p2, p3 in gz["friction"]:
        e = np.exp(-p2 * p3)
        slopes.append(p1 * p2 * e / (1.0 + e) ** 2)
        at1.append(p1 / (1.0 + np.exp(-p2 * (1.0 + p3))) - p1 / (1.0 + e))
    out["friction_slope_at_zero"] = [round(s, 3) for s in slopes]
    out["friction_torque_at_1_rad_s"] = [round(float(s), 3) for s in at1]

    # the modelled 7-DOF arm: M's smallest eigenvalue, the modes w T, the camera image
    robot = load_robot(PANDA / "robot.toml")
    model, rdata = robot.model, robot.model.createData()
    Ks, Mm = np.array(spec.actuators.Ks), np.array(spec.actuators.Mm)
    T = spec.model.T
    lo7, hi7 = model.lowerPositionLimit, model.upperPositionLimit
    min_eig, wT, Jmin = np.inf, np.zeros(7), np.full(7, np.inf)
    Jfree = np.full(7, np.inf)
    for _ in range(200):
        q = rng.uniform(lo7, hi7)
        M = pin.crba(model, rdata, q)
        M = np.triu(M) + np.triu(M, 1).T
        min_eig = min(min_eig, float(np.linalg.eigvalsh(M)[0]))
        J = 1.0 / np.diag(np.linalg.inv(M))  # the joint's inertia with the others free
        Jmin = np.minimum(Jmin, np.diag(M))
        Jfree = np.minimum(Jfree, J)
        wT = np.maximum(wT, np.sqrt(Ks * (1.0 / J + 1.0 / Mm)) * T)
    out["min_eig_M"] = min_eig
    out["smallest_diag_M"] = Jmin.round(5).tolist()
    out["smallest_J_others_free"] = Jfree.round(5).tolist()
    out["wT_max_per_joint"] = wT.round(3).tolist()
    out["mode_hz_max_per_joint"] = (wT / T / (2 * np.pi)).round(1).tolist()
    cam = robot.camera
    from amsfe_sym.apps.reference import PinocchioModel

    pm = PinocchioModel(robot, np.eye(2 * robot.n + robot.p))
    uv, depths = [], []
    for _ in range(20000):
        q = rng.uniform(lo7, hi7)
        y, _, dep = pm.camera_measure(q)
        uv.append(y)
        depths.append(dep)
    uv_a = np.array(uv)
    out["camera"] = {
        "u_px": [round(float(uv_a[:, 0].min()), 1), round(float(uv_a[:, 0].max()), 1)],
        "v_px": [round(float(uv_a[:, 1].min()), 1), round(float(uv_a[:, 1].max()), 1)],
        "depth_m": [round(min(depths), 3), round(max(depths), 3)],
        "samples": 20000,
        "width": cam.width,
        "height": cam.height,
    }
    print(json.dumps(out, indent=2))
    return out


def main() -> None:
    what = sys.argv[1] if len(sys.argv) > 1 else "check"
    if what == "urdf":
        print(f"wrote {write_urdf()}")
    elif what == "check":
        res = check()
        dest = ROOT / "docs" / "data" / "panda.json"
        dest.write_text(json.dumps(res, indent=2) + "\n")
        print(f"wrote {dest}")
    else:
        sys.exit(f"usage: {sys.argv[0]} urdf|check")


if __name__ == "__main__":
    main()
