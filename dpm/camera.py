"""Pinhole camera: horizontal field of view, row 0 at the top, as Mitsuba's `perspective`."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dpm.errors import InputError


@dataclass(frozen=True)
class Camera:
    """A pinhole camera looking from `origin` at `target`; `fov` is horizontal, in degrees."""

    origin: np.ndarray  # (3,) float64 world position
    target: np.ndarray  # (3,) float64 world position looked at
    up: np.ndarray  # (3,) float64 approximate up direction
    fov: float  # horizontal field of view, degrees
    width: int  # pixels
    height: int  # pixels

    def basis(self) -> np.ndarray:
        """(4, 3) float64 rows: origin, forward, right·tan(fov/2), up·tan(fov/2)·height/width.

        The ray through image point (x, y) in pixels (x right, y down, pixel centres at +0.5)
        has direction forward + (2x/W − 1)·right + (1 − 2y/H)·up, unnormalised. Made once
        per camera (a render's passes ask for it several times each) and shared: read it only.
        """
        cached = self.__dict__.get("_basis")
        if cached is None:
            cached = self._make_basis()
            object.__setattr__(self, "_basis", cached)  # (frozen: a cache, not a field)
        return cached

    def _make_basis(self) -> np.ndarray:
        """`basis`, computed."""
        forward = self.target - self.origin
        forward = forward / np.linalg.norm(forward)
        right = np.cross(forward, self.up)
        right /= np.linalg.norm(right)
        true_up = np.cross(right, forward)
        half = math.tan(math.radians(self.fov) / 2)
        return np.stack(
            [self.origin, forward, right * half, true_up * half * self.height / self.width]
        ).astype(np.float64)

    def with_resolution(self, width: int | None, height: int | None) -> Camera:
        """The same camera at another resolution; the horizontal field of view is kept."""
        return Camera(
            self.origin,
            self.target,
            self.up,
            self.fov,
            width or self.width,
            height or self.height,
        )

    def footprint(self, position: np.ndarray) -> np.ndarray:
        """(N,) float64 width of a pixel (scene units) at points (N, 3) seen straight from
        the camera: its angular width times the distance (a mirror or lens on the way is
        ignored)."""
        angle = 2 * math.tan(math.radians(self.fov) / 2) / self.width
        distance = np.linalg.norm(np.asarray(position, np.float64) - self.origin, axis=1)
        return angle * distance


def make_camera(
    origin: object,
    target: object,
    up: object = (0.0, 1.0, 0.0),
    fov: object = 40.0,
    width: object = 256,
    height: object = 256,
    where: str = "camera",
) -> Camera:
    """Validate raw values (e.g. from TOML) into a Camera; `where` prefixes error messages."""

    def vec3(name: str, value: object) -> np.ndarray:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.empty(0)
        if arr.shape != (3,) or not np.all(np.isfinite(arr)):
            raise InputError(f"{where}: '{name}' must be a list of 3 finite numbers")
        return arr

    o, t, u = vec3("origin", origin), vec3("target", target), vec3("up", up)
    if not isinstance(fov, int | float) or isinstance(fov, bool) or not 0 < fov < 180:
        raise InputError(f"{where}: 'fov' must be a number of degrees between 0 and 180")
    for name, value in (("width", width), ("height", height)):
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 16384:
            raise InputError(f"{where}: '{name}' must be an integer from 1 to 16384")
    forward = t - o
    if np.linalg.norm(forward) == 0:
        raise InputError(f"{where}: 'origin' and 'target' are the same point")
    if np.linalg.norm(np.cross(forward / np.linalg.norm(forward), u)) < 1e-6:
        raise InputError(f"{where}: 'up' is parallel to the viewing direction")
    return Camera(o, t, u, float(fov), int(width), int(height))


def framing_camera(lo: np.ndarray, hi: np.ndarray, width: int = 256, height: int = 256) -> Camera:
    """A camera on +z, slightly above, that sees the whole box [lo, hi] (scene units)."""
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6)
    fov = 40.0
    # The vertical field of view is the narrower one on wide images; fit the sphere in both.
    half = math.radians(fov) / 2
    half_v = math.atan(math.tan(half) * height / width)
    distance = radius / math.sin(min(half, half_v))
    direction = np.array([0.0, 0.35, 1.0])
    origin = centre + distance * direction / np.linalg.norm(direction)
    return Camera(origin, centre, np.array([0.0, 1.0, 0.0]), fov, width, height)
