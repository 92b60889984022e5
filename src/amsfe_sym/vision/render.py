"""The marker as a camera sees it: a rendered 8-bit grey image (docs/camera.md, "Simulated
images").

The marker is a square of side ``size`` [m] centred on the tracked point, facing the camera
(its plane normal to the optical axis, its edges along the image axes, in a white quiet zone
of :data:`QUIET` of its side); its corners are projected by the true pinhole (the generated
camera map's K, R_cw, position), the image is warped through the true camera's distortion
(the CameraInfo's model), then blurred (the optics and motion) and given Gaussian pixel
noise (the sensor), and rounded to uint8.  The diagonals of the projected square meet at the
pinhole's pixel of the tracked point, so a detection checks against the generated map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amsfe_sym.vision.camera_info import CameraInfo, distort, undistort
from amsfe_sym.vision.spec import MarkerSpec

__all__ = ["QUIET", "ImageNoise", "MarkerRenderer", "marker_corners"]

FloatArray = NDArray[np.float64]
U8Array = NDArray[np.uint8]

#: The white margin around the marker, per side, as a fraction of its side.
QUIET = 0.3


@dataclass(frozen=True)
class ImageNoise:
    """How the rendered image departs from the ideal one.

    Attributes:
        blur_px: Standard deviation of the Gaussian blur [px] (optics, motion), >= 0.
        noise_std: Standard deviation of the additive pixel noise [grey levels], >= 0.
        black, white: Grey levels of the marker's black and white (the exposure's contrast).
        background: Grey level around the quiet zone.
    """

    blur_px: float = 0.8
    noise_std: float = 4.0
    black: float = 30.0
    white: float = 220.0
    background: float = 110.0


def marker_corners(
    K: ArrayLike, R_cw: ArrayLike, position: ArrayLike, r_world: ArrayLike, size: float
) -> FloatArray:
    """The 4 corners (4, 2) [px], OpenCV's order (top left, top right, bottom right, bottom
    left), of a square of side ``size`` [m] centred on ``r_world`` [m] and facing the pinhole
    camera (K, R_cw, position): ``pc + size/2 (+-1, +-1, 0)`` in the camera frame, projected."""
    Km = np.asarray(K, dtype=np.float64)
    pc = np.asarray(R_cw, dtype=np.float64) @ (
        np.asarray(r_world, dtype=np.float64) - np.asarray(position, dtype=np.float64)
    )
    h = 0.5 * size
    offs = np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])
    P = pc + offs
    uv = np.column_stack(
        [Km[0, 0] * P[:, 0] / P[:, 2] + Km[0, 2], Km[1, 1] * P[:, 1] / P[:, 2] + Km[1, 2]]
    )
    return uv


class MarkerRenderer:
    """Renders the marker of ``spec`` into ``info``'s raw (distorted) image.

    The per-pixel undistortion of the image is computed once, here; each frame then costs a
    homography over the marker's bounding box, one ``cv2.remap``, a blur and the noise.
    """

    def __init__(self, info: CameraInfo, spec: MarkerSpec, noise: ImageNoise = ImageNoise()):
        import cv2

        from amsfe_sym.vision.marker import _dictionary_id

        self.info, self.spec, self.noise = info, spec, noise
        dictionary = cv2.aruco.getPredefinedDictionary(_dictionary_id(spec.dictionary))
        side = 8 * 40  # the marker's texture [texels]; bits of 40 texels
        tag = cv2.aruco.generateImageMarker(dictionary, spec.id, side, borderBits=1)
        m = round(QUIET * side)
        tex = np.full((side + 2 * m, side + 2 * m), 255, np.uint8)
        tex[m : m + side, m : m + side] = tag
        lo, hi = noise.black, noise.white
        texture = (lo + (hi - lo) * (tex.astype(np.float32) / 255.0)).astype(np.float32)
        # halved by area averaging down to 16 texels: level l has 2^l texels per texel of 0
        self._levels: list[NDArray[np.float32]] = [texture]
        while self._levels[-1].shape[0] >= 32:
            half = cv2.resize(self._levels[-1], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
            self._levels.append(np.asarray(half, np.float32))
        # the black square's corners in texel-centre coordinates (a texel's edge is at -0.5)
        a, b = m - 0.5, m + side - 0.5
        self._square = np.array([[a, a], [b, a], [b, b], [a, b]], dtype=np.float64)
        self._side = side
        self._tex_side = side + 2 * m
        w, h = info.width, info.height
        xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
        und = undistort(info, np.column_stack([xs.ravel(), ys.ravel()]))
        self._und = und.reshape(h, w, 2)

    def render(
        self, corners: ArrayLike | None, rng: np.random.Generator, foreshortened: bool = False
    ) -> U8Array:
        """The raw image (height, width) uint8 of the marker whose corners are ``corners``
        (4, 2) [px] in the rectified (pinhole) image, OpenCV's order; None: the image
        without the marker (the camera does not see it: vision/marker_pose.py).

        ``foreshortened``: the texture is averaged down to the scale of the square's shortest
        edge (a marker seen obliquely is compressed along one direction); otherwise to its
        top edge's (the square facing the camera, all four edges alike)."""
        import cv2

        info, nz = self.info, self.noise
        img = np.full((info.height, info.width), nz.background, np.float32)
        if corners is not None:
            c = np.asarray(corners, dtype=np.float64).reshape(4, 2)
            edges = np.linalg.norm(c - np.roll(c, -1, axis=0), axis=1)
            self._draw(img, c, float(edges.min() if foreshortened else edges[0]))
        if nz.blur_px > 0:
            img = np.asarray(cv2.GaussianBlur(img, (0, 0), nz.blur_px), np.float32)
        if nz.noise_std > 0:
            img += np.float32(nz.noise_std) * rng.standard_normal(img.shape, dtype=np.float32)
        out: U8Array = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        return out

    def _draw(self, img: NDArray[np.float32], c: FloatArray, edge: float) -> None:
        """Warp the marker's texture, its square at ``c`` (4, 2) [px] in the pinhole image
        and averaged to ``edge`` [px] a side, into the raw image ``img`` (in place)."""
        import cv2

        info, nz = self.info, self.noise
        H = cv2.getPerspectiveTransform(self._square.astype(np.float32), c.astype(np.float32))
        H = np.asarray(H, dtype=np.float64)
        # the quiet zone's outline in the raw image (edges sampled: distortion bends them)
        s = self._tex_side
        t = np.linspace(0.0, s, 9)
        outline = np.concatenate(
            [np.column_stack([t, 0 * t]), np.column_stack([t, 0 * t + s]),
             np.column_stack([0 * t, t]), np.column_stack([0 * t + s, t])]
        )  # fmt: skip
        rect = cv2.perspectiveTransform(outline.reshape(-1, 1, 2), H).reshape(-1, 2)
        raw = distort(info, rect)
        if np.isfinite(raw).all():
            x0, y0 = np.floor(raw.min(axis=0)).astype(int) - 3
            x1, y1 = np.ceil(raw.max(axis=0)).astype(int) + 4
            x0, y0 = max(x0, 0), max(y0, 0)
            x1, y1 = min(x1, info.width), min(y1, info.height)
            if x1 > x0 and y1 > y0:
                und = self._und[y0:y1, x0:x1].reshape(-1, 1, 2)
                tex = cv2.perspectiveTransform(und, np.linalg.inv(H)).reshape(y1 - y0, x1 - x0, 2)
                # area-average the texture down to about 2 texels per image pixel first
                scale = edge / self._side  # [px / texel]
                level = 0
                while scale * 2.0**level < 0.5 and level + 1 < len(self._levels):
                    level += 1
                texture, f = self._levels[level], 2.0**level
                # (a texel of the halved texture covers two: centre (X + 0.5) / 2 - 0.5)
                map_x = ((tex[..., 0] + 0.5) / f - 0.5).astype(np.float32)
                map_y = ((tex[..., 1] + 0.5) / f - 0.5).astype(np.float32)
                patch = cv2.remap(
                    texture, map_x, map_y, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=float(nz.background),
                )  # fmt: skip
                img[y0:y1, x0:x1] = patch
