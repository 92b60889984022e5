"""Image messages -> 8-bit grey images (docs/camera.md, "Images in").

``sensor_msgs/Image`` in ``mono8``, ``rgb8``, ``bgr8`` (also ``rgba8``/``bgra8``, whose
alpha is dropped) and ``sensor_msgs/CompressedImage`` in ``jpeg`` or ``png``, as the
``usb_cam`` / ``image_transport`` drivers write them; anything else is refused in one line.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.errors import LogError, describe

__all__ = ["ENCODINGS", "FORMATS", "GreyImage", "UndecodableImageError", "grey_from_message"]

U8Array = NDArray[np.uint8]

#: Raw encodings read: channels per pixel and the OpenCV conversion to grey (None: grey).
ENCODINGS: dict[str, tuple[int, int | None]] = {}
#: CompressedImage formats read (the ``format`` field names one of them, e.g. ``jpeg`` or
#: image_transport's ``bgr8; jpeg compressed bgr8``).
FORMATS = ("jpeg", "jpg", "png")


def _encodings() -> dict[str, tuple[int, int | None]]:
    if not ENCODINGS:
        import cv2

        ENCODINGS.update(
            {
                "mono8": (1, None),
                "8UC1": (1, None),
                "rgb8": (3, cv2.COLOR_RGB2GRAY),
                "bgr8": (3, cv2.COLOR_BGR2GRAY),
                "rgba8": (4, cv2.COLOR_RGBA2GRAY),
                "bgra8": (4, cv2.COLOR_BGRA2GRAY),
            }
        )
    return ENCODINGS


class UndecodableImageError(LogError):
    """A CompressedImage whose bytes do not decode (a corrupt or truncated jpeg or png).

    Attributes:
        stamp_ns: Its ``header.stamp`` [ns] (the message itself was read).
    """

    def __init__(self, message: str, stamp_ns: int) -> None:
        super().__init__(message)
        self.stamp_ns = stamp_ns


@dataclass(frozen=True)
class GreyImage:
    """One decoded image.

    Attributes:
        stamp_ns: ``header.stamp`` [ns]: the exposure.
        pixels: (height, width) uint8.
    """

    stamp_ns: int
    pixels: U8Array


def _stamp(msg: Any) -> int:
    s = msg.header.stamp
    sec = getattr(s, "sec", None)
    if sec is None:  # ROS 1 time
        return int(s.secs) * 1_000_000_000 + int(s.nsecs)
    return int(sec) * 1_000_000_000 + int(s.nanosec)


def _bytes(data: Any) -> U8Array:
    """A message's ``data`` as uint8 (a numpy array as it is: no copy)."""
    if isinstance(data, np.ndarray):
        return np.asarray(data, dtype=np.uint8).ravel()
    return np.frombuffer(bytes(data), dtype=np.uint8)


def grey_from_message(msg: Any, msgtype: str, where: str = "image") -> GreyImage:
    """An ``Image`` or ``CompressedImage`` (rosbags or rclpy message) as a grey image.

    Raises:
        LogError: an encoding or format not supported, a buffer of the wrong size;
            UndecodableImageError (a LogError): compressed bytes that do not decode.
    """
    import cv2

    if msgtype.endswith("CompressedImage"):
        fmt = str(msg.format).lower()
        if not any(f in fmt for f in FORMATS):
            raise LogError(
                describe(
                    f"{where} format",
                    f"a CompressedImage in {list(FORMATS[::2])}",
                    repr(msg.format),
                    "record jpeg or png (image_transport's compressed), or raw images",
                )
            )
        buf = _bytes(msg.data)
        # (straight to grey: libjpeg skips the colour planes' upsampling and conversion)
        img = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE) if buf.size else None
        if img is None:
            found = f"{buf.size} bytes"
            raise UndecodableImageError(
                describe(where, f"{msg.format} bytes that decode", found, "re-record"), _stamp(msg)
            )
        return GreyImage(_stamp(msg), np.ascontiguousarray(img, dtype=np.uint8))
    enc = str(msg.encoding)
    table = _encodings()
    if enc not in table:
        raise LogError(
            describe(
                f"{where} encoding",
                f"one of {[e for e in table if e != '8UC1']}",
                repr(enc),
                "set the driver to mono8, rgb8 or bgr8 (or record its compressed topic)",
            )
        )
    ch, code = table[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = _bytes(msg.data)
    if h <= 0 or w <= 0 or step < w * ch or data.size < h * step:
        raise LogError(
            describe(
                where,
                f"{h} rows of step >= {w * ch} bytes ({enc}, {w} px wide)",
                f"step {step}, {data.size} bytes",
                "re-record the image topic",
            )
        )
    rows = data[: h * step].reshape(h, step)[:, : w * ch]
    img = rows.reshape(h, w, ch) if ch > 1 else rows
    grey = img if code is None else cv2.cvtColor(np.ascontiguousarray(img), code)
    return GreyImage(_stamp(msg), np.ascontiguousarray(grey, dtype=np.uint8))
