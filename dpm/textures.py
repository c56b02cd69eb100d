"""Diffuse colour textures (MTL `map_Kd`): images read once, decoded to linear RGB and packed
into one array the kernels index.

An 8- or 16-bit image holds sRGB-encoded colour and is decoded to linear reflectance; a float
image (EXR, HDR) is taken as linear already. Alpha is dropped and a grey image is spread over
RGB. The texture multiplies the material's Kd, as the MTL format says.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpm.errors import InputError


@dataclass(frozen=True)
class Textures:
    """Every texture of a scene in one array (struct of arrays)."""

    index: np.ndarray  # (M,) int32 texture of each material, -1: none (Kd alone)
    texels: np.ndarray  # (N, 3) float32 linear RGB, each texture's rows top to bottom
    dims: np.ndarray  # (K, 3) int64 first texel, width, height of each texture


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """Linear values of sRGB-encoded values x in [0, 1] (IEC 61966-2-1)."""
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def read_texture(path: Path) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of the image at path."""
    if not path.is_file():
        raise InputError(f"{path}: texture file not found")
    import imageio.v3 as iio  # here: only scenes with textures pay for the import

    try:
        image = np.asarray(iio.imread(path))
    except Exception as exc:  # imageio raises many kinds for unreadable images
        raise InputError(f"{path}: cannot read the texture ({type(exc).__name__})") from None
    if image.ndim == 2:
        image = image[..., None]
    if image.ndim != 3 or image.shape[0] == 0 or image.shape[1] == 0:
        raise InputError(f"{path}: a texture must be a 2-D image (got shape {image.shape})")
    rgb = np.repeat(image[..., :1], 3, axis=2) if image.shape[2] < 3 else image[..., :3]
    if np.issubdtype(rgb.dtype, np.integer):
        linear = srgb_to_linear(rgb / float(np.iinfo(rgb.dtype).max))
    else:
        linear = rgb.astype(np.float64)
    if not np.all(np.isfinite(linear)) or linear.min() < 0 or linear.max() > 1:
        raise InputError(f"{path}: a reflectance texture's values must lie in [0, 1]")
    return linear.astype(np.float32)


def pack_textures(files: list[Path | None]) -> Textures | None:
    """The Textures of materials whose map_Kd files are `files` (None: untextured); None when
    no material has one. A file used by several materials is read once."""
    if all(f is None for f in files):
        return None
    order: dict[Path, int] = {}
    images: list[np.ndarray] = []
    index = np.full(len(files), -1, np.int32)
    for m, f in enumerate(files):
        if f is None:
            continue
        if f not in order:
            order[f] = len(images)
            images.append(read_texture(f))
        index[m] = order[f]
    sizes = [im.shape[0] * im.shape[1] for im in images]
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    shapes = [(im.shape[1], im.shape[0]) for im in images]  # width, height
    dims = np.array([[o, w, h] for o, (w, h) in zip(first, shapes, strict=True)], np.int64)
    texels = np.concatenate([im.reshape(-1, 3) for im in images])
    return Textures(index=index, texels=np.ascontiguousarray(texels), dims=dims)
