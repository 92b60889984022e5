"""What the camera chain looks for: the marker (dictionary, id, size, which point) and where
the camera's calibration comes from.  A value module (no OpenCV at import): the topic spec's
``[marker]`` and ``[camera]`` sections parse into it (docs/camera.md).

```toml
[topics]
camera = "/camera/image_raw"      # an Image or CompressedImage topic: detected here

[camera]
info = "/camera/camera_info"      # CameraInfo topic (default: the log's one CameraInfo topic)

[marker]
dictionary = "DICT_APRILTAG_36h11"   # any cv2.aruco dictionary name
id = 0                            # the marker's id in it
size = 0.05                       # its black square's side [m]
point = "centre"                  # or "top_left" | "top_right" | "bottom_right" | "bottom_left"
pixel_std = 0.15                  # the detected point's standard deviation per axis [px]
refinement = "subpix"             # corner refinement (default: subpix; edges for --corners)
max_foreshortening_deg = 50.0     # frames whose marker looks more oblique are skipped (90: none)
```
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from amsfe_sym.core.values import read_int, read_number
from amsfe_sym.errors import ConfigError, describe

__all__ = [
    "CORNERS",
    "DICTIONARIES",
    "IMAGE_TYPES",
    "MAX_FORESHORTENING_DEG",
    "REFINEMENTS",
    "MarkerSpec",
    "parse_camera_section",
    "parse_marker",
]

#: The message types of an image topic (the camera role takes them beside a pixel topic).
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"

#: The marker's corners in OpenCV's order (clockwise from the top left of the marker as
#: printed); ``centre`` is the intersection of the diagonals.
CORNERS = ("top_left", "top_right", "bottom_right", "bottom_left")
Point = Literal["centre", "top_left", "top_right", "bottom_right", "bottom_left"]

#: How the detector refines the marker's corners: ``subpix`` (OpenCV's
#: ``CORNER_REFINE_SUBPIX``), ``edges`` (then the marker's 4 outer edges fitted and
#: intersected: :func:`~amsfe_sym.vision.edges.edge_corners`, unbiased where ``subpix`` puts
#: the corners 0.15-0.5 px inside, at ~3x the detection's CPU), or OpenCV's ``contour`` /
#: ``apriltag`` (for comparison: tools/marker_view_accuracy.py ``--bias``).
REFINEMENTS: tuple[str, ...] = ("subpix", "edges", "contour", "apriltag")

#: The default ``[marker] max_foreshortening_deg`` [deg]: on the calibration recordings' views
#: (25-60 px markers, tools/marker_view_accuracy.py ``--recording``) the centre of ``subpix``
#: corners is unbiased to within its standard error on markers foreshortened less than 50
#: deg, and carries an error of the view of 0.05-0.5 px (growing with the angle) beyond.
MAX_FORESHORTENING_DEG = 50.0

#: The cv2.aruco dictionaries by name (resolved by :mod:`amsfe_sym.vision.marker`).
DICTIONARIES = (
    "DICT_4X4_50", "DICT_4X4_100", "DICT_4X4_250", "DICT_4X4_1000",
    "DICT_5X5_50", "DICT_5X5_100", "DICT_5X5_250", "DICT_5X5_1000",
    "DICT_6X6_50", "DICT_6X6_100", "DICT_6X6_250", "DICT_6X6_1000",
    "DICT_7X7_50", "DICT_7X7_100", "DICT_7X7_250", "DICT_7X7_1000",
    "DICT_ARUCO_ORIGINAL", "DICT_ARUCO_MIP_36h12",
    "DICT_APRILTAG_16h5", "DICT_APRILTAG_25h9", "DICT_APRILTAG_36h10", "DICT_APRILTAG_36h11",
)  # fmt: skip


@dataclass(frozen=True)
class MarkerSpec:
    """The fiducial the camera tracks.

    Attributes:
        dictionary: A ``cv2.aruco`` dictionary name (:data:`DICTIONARIES`; AprilTag
            families included).
        id: The marker's id in the dictionary (another id seen is skipped, counted).
        size: Side of the marker's black square [m] (the renderer draws it this size).
        point: The tracked point: ``centre`` (intersection of the diagonals, the
            projection of the square's centre) or a named corner (:data:`CORNERS`).
        pixel_std: Standard deviation of the detected point per axis [px]; the default
            bounds the spread measured on rendered images of 20-60 px markers
            (tests/test_vision_marker.py, docs/camera.md): the value for ``[filter]
            camera_pixel_std`` when the images are this clean.
        refinement: How the corners are refined (:data:`REFINEMENTS`); None: the
            command's choice, ``subpix`` for the tracked point (the centre is unbiased by
            symmetry) and ``edges`` for ``amsfe calibrate --corners`` (the marker's extent
            matters there: docs/camera.md, "The corners").
        max_foreshortening_deg: The most foreshortened marker [deg] whose frame is used
            (:func:`~amsfe_sym.vision.marker.foreshortening` of the detected corners: arccos
            of the marker's narrower over its wider extent in the image; near the image's
            centre, its angle from face-on); more, the frame is skipped and counted (the
            centre of a marker seen more obliquely carries an error of the view that its
            frames share: docs/camera.md, "The corners").  90: no limit.
    """

    dictionary: str = "DICT_APRILTAG_36h11"
    id: int = 0
    size: float = 0.05
    point: Point = "centre"
    pixel_std: float = 0.15
    refinement: str | None = None
    max_foreshortening_deg: float = MAX_FORESHORTENING_DEG


def parse_marker(table: dict[str, Any], where: str = "[marker]") -> MarkerSpec:
    """A :class:`MarkerSpec` from the topic spec's ``[marker]`` table.

    Raises:
        ConfigError: an unknown key, dictionary or point; an id < 0; a size or std <= 0.
    """
    known = (
        "dictionary", "id", "size", "point", "pixel_std", "refinement", "max_foreshortening_deg"
    )  # fmt: skip
    bad = sorted(set(table) - set(known))
    if bad:
        raise ConfigError(describe(where, f"keys among {list(known)}", str(bad), "drop them"))
    out: dict[str, Any] = {}
    if "dictionary" in table:
        d = table["dictionary"]
        names = {n.lower(): n for n in DICTIONARIES}
        if not isinstance(d, str) or d.lower() not in names:
            raise ConfigError(
                describe(f"{where} dictionary", f"one of {list(DICTIONARIES)}", repr(d), "fix it")
            )
        out["dictionary"] = names[d.lower()]
    if "id" in table:
        out["id"] = read_int(table["id"], f"{where} id", ConfigError, 0)
    if "size" in table:
        out["size"] = read_number(table["size"], f"{where} size", ConfigError, 0.0, strict=True)
    if "pixel_std" in table:
        out["pixel_std"] = read_number(
            table["pixel_std"], f"{where} pixel_std", ConfigError, 0.0, strict=True
        )
    if "max_foreshortening_deg" in table:
        key = f"{where} max_foreshortening_deg"
        deg = read_number(table["max_foreshortening_deg"], key, ConfigError, 0.0, strict=True)
        if deg > 90.0:
            raise ConfigError(describe(key, "an angle in (0, 90] deg", repr(deg), "fix it"))
        out["max_foreshortening_deg"] = deg
    if "refinement" in table:
        r = table["refinement"]
        if r not in REFINEMENTS:
            raise ConfigError(
                describe(f"{where} refinement", f"one of {list(REFINEMENTS)}", repr(r), "fix it")
            )
        out["refinement"] = r
    if "point" in table:
        p = table["point"]
        if p not in ("centre", *CORNERS):
            raise ConfigError(
                describe(f"{where} point", f"'centre' or one of {list(CORNERS)}", repr(p), "fix it")
            )
        out["point"] = p
    return MarkerSpec(**out)


def parse_camera_section(table: dict[str, Any], where: str = "[camera]") -> str | None:
    """The CameraInfo topic of the topic spec's ``[camera]`` table (None: not named).

    Raises:
        ConfigError: an unknown key, or a topic name that does not start with ``/``.
    """
    bad = sorted(set(table) - {"info", "time_offset"})  # time_offset: topics.spec reads it
    if bad:
        raise ConfigError(
            describe(where, "keys among ['info', 'time_offset']", str(bad), "drop them")
        )
    if "info" not in table:
        return None
    v = table["info"]
    if not isinstance(v, str) or not v.startswith("/") or " " in v:
        raise ConfigError(describe(f"{where} info", "a topic name like '/x'", repr(v), "fix it"))
    return v
