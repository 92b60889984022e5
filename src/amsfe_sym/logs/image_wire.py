"""Image payloads read in place (docs/camera.md, "Speed"): the fields of a
``sensor_msgs/Image`` or ``CompressedImage`` that the camera chain uses, straight from the
payload's bytes, the pixels (or the jpeg / png bytes) a view of the payload, never copied.

``rosbags``' deserializer copies a 640 x 480 image into a new array and builds the message
in Python (~0.5 ms a frame, as much as a detection in a region of interest); this reads the
few fixed fields with ``struct`` and takes the data as a numpy view.  The rules are those of
:mod:`amsfe_sym.logs.layout`'s walk: CDR (ROS 2) aligns each primitive to its size relative
to the payload after the 4-byte encapsulation header and counts a string's NUL, ROS 1 has no
alignment, no NUL and a ``uint32 seq`` before the stamp.  Anything else (big-endian CDR, a
length past the end) goes to the reference (:func:`amsfe_sym.logs.decode.deserialize`),
which decodes it or refuses it in one line; tests/test_vision_speed.py compares both on
every encoding and container.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amsfe_sym.logs.decode import deserialize
from amsfe_sym.logs.layout import Encoding, UnusualError

__all__ = ["CompressedImageView", "ImageView", "Stamp", "image_message"]

U8Array = NDArray[np.uint8]

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


@dataclass(frozen=True)
class Stamp:
    """``header.stamp``: ``sec`` [s] and ``nanosec`` [ns] (ROS 1's secs / nsecs too)."""

    sec: int
    nanosec: int


@dataclass(frozen=True)
class _Header:
    stamp: Stamp


@dataclass(frozen=True)
class ImageView:
    """A ``sensor_msgs/Image``'s fields; ``data``: a view of the payload's pixel bytes."""

    header: _Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: U8Array


@dataclass(frozen=True)
class CompressedImageView:
    """A ``sensor_msgs/CompressedImage``'s fields; ``data``: a view of its encoded bytes."""

    header: _Header
    format: str
    data: U8Array


class _Cursor:
    """Reads a payload left to right (``base``: where CDR's alignment counts from)."""

    def __init__(self, raw: Any, cdr: bool) -> None:
        self.mv = memoryview(raw).cast("B")
        self.cdr = cdr
        self.base = 4 if cdr else 0
        self.pos = self.base

    def align(self, size: int) -> None:
        if self.cdr:
            self.pos += -(self.pos - self.base) % size

    def u32(self) -> int:
        self.align(4)
        if self.pos + 4 > len(self.mv):
            raise UnusualError
        (v,) = _U32.unpack_from(self.mv, self.pos)
        self.pos += 4
        return int(v)

    def u8(self) -> int:
        if self.pos + 1 > len(self.mv):
            raise UnusualError
        v = self.mv[self.pos]
        self.pos += 1
        return int(v)

    def string(self) -> str:
        n = self.u32()
        if self.pos + n > len(self.mv) or (self.cdr and (n == 0 or self.mv[self.pos + n - 1])):
            raise UnusualError  # (CDR strings end with a NUL, counted)
        text = bytes(self.mv[self.pos : self.pos + n - (1 if self.cdr else 0)])
        self.pos += n
        return text.decode("utf-8")

    def header(self) -> _Header:
        if not self.cdr:
            self.u32()  # (ROS 1: seq)
        self.align(4)
        if self.pos + 8 > len(self.mv):
            raise UnusualError
        sec, nanosec = _STAMP.unpack_from(self.mv, self.pos)
        if not self.cdr:
            sec = int(sec) & 0xFFFFFFFF  # (ROS 1's time is unsigned)
        self.pos += 8
        self.string()  # frame_id
        return _Header(Stamp(int(sec), int(nanosec)))

    def data(self, raw: Any) -> U8Array:
        n = self.u32()
        if self.pos + n > len(self.mv) or len(self.mv) - (self.pos + n) > (3 if self.cdr else 0):
            raise UnusualError  # (past the end, or bytes after it other than CDR's padding)
        start = self.pos
        self.pos += n
        return np.frombuffer(raw, dtype=np.uint8, count=n, offset=start)


def _read(raw: Any, msgtype: str, encoding: Encoding) -> ImageView | CompressedImageView:
    cdr = encoding == "cdr"
    if cdr and bytes(memoryview(raw).cast("B")[:2]) != b"\x00\x01":
        raise UnusualError  # (little-endian CDR only)
    c = _Cursor(raw, cdr)
    header = c.header()
    if msgtype.endswith("CompressedImage"):
        return CompressedImageView(header, c.string(), c.data(raw))
    height, width = c.u32(), c.u32()
    enc = c.string()
    big = c.u8()
    step = c.u32()
    return ImageView(header, height, width, enc, big, step, c.data(raw))


def image_message(
    raw: Any, msgtype: str, encoding: Encoding = "cdr", where: str = ""
) -> ImageView | CompressedImageView | Any:
    """One image payload (``bytes`` or a uint8 array view of the log's buffer) as a message
    :func:`amsfe_sym.vision.images.grey_from_message` takes: read in place, or by the
    reference deserializer when this reader does not take it.

    Raises:
        LogError: the reference refused it (a corrupt or mislabelled message).
    """
    try:
        return _read(raw, msgtype, encoding)
    except (UnusualError, UnicodeDecodeError, struct.error):
        return deserialize(bytes(memoryview(raw).cast("B")), msgtype, encoding, where)
