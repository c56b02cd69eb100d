"""Intel Open Image Denoise (CPU) on a rendered image, guided by its albedo and normal images.

OIDN's output does not depend on its thread count (checked in tests), so a denoised render
keeps the "same seed, same image" promise.
"""

from __future__ import annotations

import numpy as np

from dpm.density.base import luminance
from dpm.errors import InputError
from dpm.tracer.visible import VisiblePoints

RESTORE_Z = 2.0  # standard errors of a pixel's mean the denoiser may move it before undone


def denoise(
    color: np.ndarray, albedo: np.ndarray, normal: np.ndarray, clean_aux: bool = False
) -> np.ndarray:
    """(H, W, 3) float32 linear RGB after OIDN's RT filter (HDR, high quality).

    color: (H, W, 3) linear RGB radiance; albedo: (H, W, 3) in [0, 1], the reflectance of
    the first diffuse surface each pixel sees; normal: (H, W, 3) world-space normals there
    (zero where the pixel sees no surface). clean_aux: the guides are free of noise (means
    over enough paths), so OIDN follows their edges fully instead of guarding against their
    noise (its `cleanAux`).
    """
    try:
        import pyoidn
    except ImportError:
        raise InputError(
            "denoising needs pyoidn (pip install pyoidn); or pass --no-denoise"
        ) from None
    images = [np.ascontiguousarray(np.nan_to_num(a), np.float32) for a in (color, albedo, normal)]
    images[0] = np.maximum(images[0], 0.0)  # HDR input must be non-negative
    return pyoidn.denoise(*images, hdr=True, clean_aux=clean_aux, quality="high")


def restore_certain(
    color: np.ndarray, denoised: np.ndarray, error: np.ndarray, z: float = RESTORE_Z
) -> np.ndarray:
    """(H, W, 3) float32: `denoised`, except where it moved a pixel's luminance by more than
    z standard errors `error` (H, W) of the pixel's own mean: there the render's `color`
    (blended in between z and 2z). The denoiser takes a glint that every path of a pixel
    sees (a small light in water) for a firefly and wipes it; a pixel that well known needs
    no denoising. An infinite error (unknown: too few samples to tell) keeps `denoised`."""
    shift = np.abs(luminance(denoised) - luminance(color)) / np.maximum(error, 1e-30)
    keep = np.clip(shift / z - 1.0, 0.0, 1.0)[..., None]
    return (denoised + keep * (color - denoised)).astype(np.float32)


def guides(points: VisiblePoints) -> tuple[np.ndarray, np.ndarray]:
    """The denoiser's per-sample guides: (N, 3) albedo in [0, 1] and (N, 3) unit normal.

    Albedo is the first diffuse surface's reflectance tinted by the mirrors and glass on the
    way (OIDN's convention for delta surfaces); a light seen directly gets its normalised
    colour, and a miss zero albedo and normal.
    """
    albedo = np.clip(points.albedo * points.throughput, 0.0, 1.0)
    peak = points.emitted.max(axis=1, keepdims=True)
    light = ~points.hit & (peak[:, 0] > 0)
    albedo[light] = points.emitted[light] / peak[light]
    return albedo, points.normal
