"""The SSIM implementations the ``ssim`` suite sets beside flowtact's: scikit-image (the oracle),
OpenCV filters following scikit-image's definition, and OpenCV-contrib's ``quality.QualitySSIM``;
plus the regions (full frame, crop, 2× downsampled) they are compared on."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import numpy as np

from flowtact.blocks.teleop.image import centre_crop

__all__ = ["REGIONS", "WINDOWS", "OpenCvSsim", "QualitySsim", "downsample2", "region_frames", "skimage_ssim"]

Window = Literal["box7", "gauss1.5"]
#: box7: the thesis's 7×7 uniform window, sample covariance; gauss1.5: Wang et al.'s Gaussian
#: (σ = 1.5 px, 11×11 after scikit-image's 3.5 σ truncation), population covariance.
WINDOWS: tuple[Window, ...] = ("box7", "gauss1.5")
C1 = (0.01 * 255) ** 2
C2 = (0.03 * 255) ** 2


def downsample2(frames: np.ndarray) -> np.ndarray:
    """2×2 block mean of uint8 images (…, H, W), rounded half up (odd last row/column dropped)."""
    h, w = frames.shape[-2] // 2 * 2, frames.shape[-1] // 2 * 2
    f = frames[..., :h, :w].astype(np.uint16)
    s = f[..., 0::2, 0::2] + f[..., 1::2, 0::2] + f[..., 0::2, 1::2] + f[..., 1::2, 1::2]
    return ((s + 2) // 4).astype(np.uint8)


#: Region name -> (what it is, the map from full (…, 240, 320) frames to it). The shipped
#: teleop.yaml runs ``crop`` (the thesis's centred 240×90 window).
REGIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "full 240×320": lambda f: f,
    "crop 90×240": centre_crop,
    "full ↓2 120×160": downsample2,
    "crop ↓2 45×120": lambda f: downsample2(centre_crop(f)),
}


def region_frames(region: str, frames: np.ndarray) -> np.ndarray:
    """``frames`` (…, 240, 320) uint8 mapped to ``region``, contiguous."""
    return np.ascontiguousarray(REGIONS[region](frames))


def skimage_ssim(ref: np.ndarray, cur: np.ndarray, window: Window) -> float:
    """The oracle: scikit-image's ``structural_similarity`` with the window's conventions."""
    from skimage.metrics import structural_similarity

    if window == "box7":
        return float(structural_similarity(ref, cur, win_size=7, gaussian_weights=False, data_range=255))
    return float(
        structural_similarity(
            ref, cur, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255
        )
    )


class OpenCvSsim:
    """scikit-image's SSIM written with OpenCV filters (``cv2.blur`` / ``cv2.GaussianBlur``, float64),
    the reference's filtered terms cached; the mean over the windows that fit (no border windows)."""

    def __init__(self, ref: np.ndarray, window: Window) -> None:
        import cv2

        self._cv2 = cv2
        self.window = window
        self.pad = 3 if window == "box7" else 5
        self.cov = 49 / 48 if window == "box7" else 1.0
        x = ref.astype(np.float64)
        self._ux = self._filter(x)
        self._vx = self.cov * (self._filter(x * x) - self._ux * self._ux)
        self._x = x

    def _filter(self, a: np.ndarray) -> np.ndarray:
        cv2 = self._cv2
        if self.window == "box7":
            return cv2.blur(a, (7, 7), borderType=cv2.BORDER_REFLECT)
        return cv2.GaussianBlur(a, (11, 11), 1.5, borderType=cv2.BORDER_REFLECT)

    def compare(self, cur: np.ndarray) -> float:
        y = cur.astype(np.float64)
        uy = self._filter(y)
        vy = self.cov * (self._filter(y * y) - uy * uy)
        vxy = self.cov * (self._filter(self._x * y) - self._ux * uy)
        ux = self._ux
        s = ((2 * ux * uy + C1) * (2 * vxy + C2)) / ((ux * ux + uy * uy + C1) * (self._vx + vy + C2))
        p = self.pad
        return float(s[p:-p, p:-p].mean())


class QualitySsim:
    """OpenCV-contrib's own ``cv2.quality.QualitySSIM`` (Gaussian 11×11, σ = 1.5, its own border
    handling: the mean runs over the whole map, border windows included)."""

    def __init__(self, ref: np.ndarray) -> None:
        import cv2

        self._q = cv2.quality.QualitySSIM_create(ref)

    def compare(self, cur: np.ndarray) -> float:
        return float(self._q.compute(cur)[0])
