"""Image and JSON output, written atomically: a temporary file beside the target, then rename."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import OpenEXR

from dpm.errors import InputError


@contextlib.contextmanager
def atomic(path: Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success it replaces `path`, else it is removed."""
    if not path.parent.is_dir():
        raise InputError(f"{path}: output folder does not exist")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)  # mkstemp makes 0600 files; give outputs the usual mode
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except OSError as exc:
        raise InputError(f"{path}: cannot write: {exc.strerror or exc}") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


KNEE = 0.8  # linear values above this roll off towards 1 instead of clipping


def tone_map(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) linear RGB into [0, 1): identity up to KNEE, then the shoulder
    KNEE + (1 - KNEE) t / (1 + t), t = (m - KNEE) / (1 - KNEE), on each pixel's largest
    channel m, the three channels scaled alike (hue kept). It is slow enough that caustics up
    to about 20 (in linear units) still get distinct 8-bit levels instead of clipping to white."""
    x = np.maximum(np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=1e30), 0.0)
    m = x.max(axis=-1, keepdims=True)
    span = 1.0 - KNEE
    t = np.maximum(m - KNEE, 0.0) / span
    scale = np.where(m > KNEE, (KNEE + span * t / (1.0 + t)) / np.maximum(m, 1e-30), 1.0)
    return np.minimum(x * scale, 1.0)


def linear_to_srgb8(image: np.ndarray) -> np.ndarray:
    """sRGB-encode linear RGB (H, W, 3) float into (H, W, 3) uint8 after `tone_map`."""
    x = tone_map(image)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write linear RGB (H, W, 3): float32 OpenEXR when the name ends in .exr, else sRGB PNG."""
    path = Path(path)
    image = np.ascontiguousarray(image, dtype=np.float32)
    with atomic(path) as tmp:
        if path.suffix.lower() == ".exr":
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            with OpenEXR.File(header, {"RGB": image}) as exr:
                exr.write(str(tmp))
        else:
            iio.imwrite(tmp, linear_to_srgb8(image), extension=".png")


def read_exr(path: str | Path) -> np.ndarray:
    """Read an RGB OpenEXR file written by `write_image` into (H, W, 3) float32."""
    with OpenEXR.File(str(path)) as exr:
        return np.asarray(exr.channels()["RGB"].pixels, dtype=np.float32)


def write_json(path: str | Path, data: dict) -> None:
    """Write a JSON document (e.g. render statistics)."""
    path = Path(path)
    with atomic(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
