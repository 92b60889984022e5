"""An image topic decoded ahead on worker threads while the log is read (docs/camera.md,
"Speed").

Decoding a jpeg is most of what a compressed image costs (~1.2 ms of CPU for 640 x 480,
against ~0.7 ms for the marker's search in its region of interest), and OpenCV releases
Python's GIL inside ``cv2.imdecode`` and the ArUco detector.  :class:`Prefetch` is the log
reader's decoder of an image topic (the contract of :func:`amsfe_sym.logs.stream.read_topics`)
that runs an :class:`~amsfe_sym.vision.detections.ImageDecoder`'s two steps off the reading
thread:

- **decode** (the payload read in place, then grey) on ``threads`` worker threads, frames in
  any order;
- **detect** on one more thread, frame after frame in the log's order, because each search
  starts in the region of interest around the previous frame's corners: the same calls on
  the same images in the same order as the serial decoder, so the same corners, bit for bit
  (tests/test_vision_prefetch.py).

Meanwhile the reading thread goes on cutting the log's chunks and decoding the other topics
(the encoders).  Memory is bounded: at most ``depth`` frames are read and not yet detected
(each holds a view of its chunk and, once decoded, its grey image); the reader waits for room
before it hands out the next one.  A slice's result is a ``Future`` the reader resolves when
it joins the topic's slices.  A frame that fails (a payload that is not an image message)
stops the work: the frames after it are not decoded and the reader raises the error at its
next slice, or when it joins the topic.  :meth:`Prefetch.close` (the reader calls it in a
``finally``: an error, Ctrl-C) cancels what is queued and joins the threads.  The reading
thread waits for room with Ctrl-C held (:func:`~amsfe_sym.core.interrupts.wait_held`): an
interruption inside the semaphore's lock left it held, the detection thread then waited for
it forever and ``amsfe estimate`` hung at its join.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

from amsfe_sym.core.interrupts import DeferredSignals, wait_held
from amsfe_sym.errors import ConfigError, describe
from amsfe_sym.vision.detections import Detections, FrameColumns, ImageDecoder
from amsfe_sym.vision.images import GreyImage

__all__ = ["DEFAULT_THREADS", "DEPTH", "THREADS_ENV", "Prefetch", "image_threads"]

#: Frames read but not yet detected, at most (each holds its payload, ~0.1-0.3 MB for a 640 x
#: 480 jpeg, by a view of its chunk, and once decoded a 0.3 MB grey image: ~10-20 MB in all).
#: Deep enough that a thread the scheduler leaves waiting for a few ms on a busy machine does
#: not stall the others (at a load of 9 on 2 cores, one decoder read the 60 s jpeg log of
#: docs/camera.md in 6.1 s with 32, 6.9 s with 8: medians of 3).
DEPTH = 32
#: Decoding threads on a machine of 2 or more cores: two decoders and one detector beside the
#: reader (a jpeg's decoding, ~1.2 ms a frame, costs more than its search, ~0.7 ms).  On 2
#: nearly quiet cores the 60 s jpeg log's ``amsfe estimate`` ran at 23x real time with 2,
#: 18x with 1, 16x serially (docs/camera.md, "Speed").
DEFAULT_THREADS = 2
#: The environment variable that sets the decoding threads (0: serial, on the reading thread).
THREADS_ENV = "AMSFE_IMAGE_THREADS"


def image_threads(value: str | None = None, compressed: bool = True) -> int:
    """Decoding threads of a log's image topic: ``value`` (default: ``$AMSFE_IMAGE_THREADS``),
    else, for ``compressed`` images (jpeg, png), :data:`DEFAULT_THREADS` on a machine of 2 or
    more cores, and 0 (serial) on one core or for raw Images (their pixels are read in place:
    there is no decoding to overlap, only the threads' hand-offs to pay).  With N >= 1 the
    reader runs N decoding threads and one detection thread beside itself
    (:class:`Prefetch`); 0 decodes and detects on the reading thread.

    Raises:
        ConfigError: not a whole number from 0 to 16.
    """
    text = os.environ.get(THREADS_ENV) if value is None else value
    if text is None or text.strip() == "":
        return DEFAULT_THREADS if compressed and (os.cpu_count() or 1) >= 2 else 0
    try:
        n = int(text)
    except ValueError:
        n = -1
    if not 0 <= n <= 16:
        raise ConfigError(
            describe(
                THREADS_ENV,
                "a whole number of image decoding threads from 0 (serial) to 16",
                repr(text),
                f"set {THREADS_ENV}=1 (or 0 to decode on the reading thread)",
            )
        )
    return n


class Prefetch:
    """``decode(payloads, encoding, where)`` of an image topic that returns a ``Future`` of
    the slice's :class:`~amsfe_sym.vision.detections.Detections` (module docstring).

    Args:
        decoder: The serial decoder whose steps run here (its ``grey`` on the decoding
            threads, its ``detect_into`` on the detection thread).
        threads: Decoding threads (>= 1).
        depth: Frames read and not yet detected, at most (>= 1).

    Attributes:
        peak: The most frames that were read and not yet detected at once (<= ``depth``).
    """

    def __init__(self, decoder: ImageDecoder, threads: int = 1, depth: int = DEPTH) -> None:
        if threads < 1 or depth < 1:
            raise ValueError(f"threads {threads} and depth {depth} must be >= 1")
        self.decoder, self.threads, self.depth = decoder, threads, depth
        self._decode = ThreadPoolExecutor(threads, thread_name_prefix="amsfe-image-decode")
        self._detect = ThreadPoolExecutor(1, thread_name_prefix="amsfe-image-detect")
        self._room = threading.Semaphore(depth)
        self._lock = threading.Lock()
        self._held = 0
        self.peak = 0
        self._failed: BaseException | None = None
        self._closed = False

    @property
    def frames(self) -> int:
        """Frames detected so far."""
        return self.decoder.frames

    def __call__(
        self, raws: Sequence[bytes], encoding: str = "cdr", where: str = ""
    ) -> Future[Detections]:
        self._raise_failed()
        cols = FrameColumns(len(raws))
        view = getattr(raws, "view", raws.__getitem__)
        for i in range(len(raws)):
            wait_held(lambda t: self._room.acquire(timeout=t))  # (Ctrl-C: raised here)
            with self._lock:
                self._held += 1
                self.peak = max(self.peak, self._held)
            try:
                self._raise_failed()
                grey = self._decode.submit(self.decoder.grey, view(i), encoding, where)
                self._detect.submit(self._detect_one, grey, cols, i)
            except BaseException:
                self._release()
                raise
        return self._detect.submit(self._slice, cols)

    def _detect_one(self, grey: Future[GreyImage], cols: FrameColumns, i: int) -> None:
        try:
            if self._failed is None:
                self.decoder.detect_into(cols, i, grey.result())
        except BaseException as exc:  # (kept; raised on the reading thread)
            if self._failed is None:
                self._failed = exc
        finally:
            self._release()

    def _slice(self, cols: FrameColumns) -> Detections:
        self._raise_failed()
        return cols.detections()

    def _release(self) -> None:
        with self._lock:
            self._held -= 1
        self._room.release()

    def _raise_failed(self) -> None:
        if self._failed is not None:
            raise self._failed

    def close(self) -> None:
        """Cancel the frames queued, wait for the ones in hand (a few ms) and end the
        threads; idempotent."""
        if self._closed:
            return
        self._closed = True
        if self._failed is None:
            self._failed = _ClosedError("the image prefetch was closed")
        with DeferredSignals():  # (the joins take locks the workers release)
            self._decode.shutdown(wait=False, cancel_futures=True)
            self._detect.shutdown(wait=True, cancel_futures=True)
            self._decode.shutdown(wait=True)

    def __enter__(self) -> Prefetch:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class _ClosedError(RuntimeError):
    """Work asked of a :class:`Prefetch` after its close."""
