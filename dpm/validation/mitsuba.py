"""Converter from a dpm scene to Mitsuba 3, the independent renderer our tests compare against.

Materials map as docs/design.md states: twosided(diffuse), twosided(conductor, material=none),
dielectric (int_ior = Ni, ext_ior = 1, specular_transmittance = Tf), `area` emitters with the
emitter's own Kd behind them; flat-shaded meshes; perspective camera with fov_axis="x" and a
box pixel filter; the `path` integrator. Run as a module it renders an example scene with both
renderers side by side (the README figure):

    python -m dpm.validation.mitsuba examples/scenes/ring.obj -o ring.png --spp 1024

Mitsuba 3 comes with the test extra (`pip install -e ".[test]"`); it is imported only inside
the functions that need it, and its absence is a one-line InputError.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from dpm.camera import Camera
from dpm.errors import InputError
from dpm.scene import DIELECTRIC, MIRROR, THIN, Scene

VARIANT = "scalar_rgb"  # runs anywhere; llvm_ad_rgb needs a libLLVM


def load_mitsuba():
    """The `mitsuba` module set to VARIANT; InputError when Mitsuba 3 is not installed."""
    try:
        import mitsuba as mi
    except ImportError:
        raise InputError(
            "Mitsuba 3 is not installed: pip install -e '.[test]' (or pip install mitsuba)"
        ) from None
    mi.set_variant(VARIANT)
    return mi


def _write_ply(path: Path, triangles: np.ndarray) -> None:
    """Binary PLY of unshared triangles (T, 3, 3) float32, winding kept."""
    t = len(triangles)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {3 * t}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {t}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    faces = np.zeros(t, dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"] = 3
    faces["v"] = np.arange(3 * t, dtype=np.int32).reshape(t, 3)
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(triangles, dtype="<f4").tobytes())
        f.write(faces.tobytes())


def _rgb(value: np.ndarray) -> dict:
    return {"type": "rgb", "value": [float(v) for v in value]}


def _bsdf(scene: Scene, m: int) -> dict:
    mats = scene.materials
    if mats.kind[m] == MIRROR:
        conductor = {
            "type": "conductor",
            "material": "none",
            "specular_reflectance": _rgb(mats.specular[m]),
        }
        return {"type": "twosided", "bsdf": conductor}
    if mats.kind[m] in (DIELECTRIC, THIN):
        return {
            "type": "dielectric" if mats.kind[m] == DIELECTRIC else "thindielectric",
            "int_ior": float(mats.ior[m]),
            "ext_ior": 1.0,
            "specular_transmittance": _rgb(mats.transmittance[m]),
        }
    return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": _rgb(mats.albedo[m])}}


def mitsuba_scene(scene: Scene, camera: Camera, spp: int, folder: Path) -> dict:
    """A Mitsuba scene dictionary for `scene` seen by `camera`; meshes are written to folder."""
    if scene.materials.textures is not None:
        raise InputError(f"{scene.path}: textured materials are not converted to Mitsuba")
    mi = load_mitsuba()
    desc: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": -1},
        "sensor": {
            "type": "perspective",
            "fov": float(camera.fov),
            "fov_axis": "x",
            "to_world": mi.ScalarTransform4f().look_at(
                origin=camera.origin.tolist(), target=camera.target.tolist(), up=camera.up.tolist()
            ),
            "film": {
                "type": "hdrfilm",
                "width": camera.width,
                "height": camera.height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "independent", "sample_count": spp},
        },
    }
    for m, name in enumerate(scene.materials.names):
        triangles = scene.triangles[scene.material == m]
        if len(triangles) == 0:
            continue
        ply = folder / f"material{m}.ply"
        _write_ply(ply, triangles)
        shape = {"type": "ply", "filename": str(ply), "face_normals": True, "bsdf": _bsdf(scene, m)}
        if scene.materials.emission[m].max() > 0:
            shape["emitter"] = {"type": "area", "radiance": _rgb(scene.materials.emission[m])}
        desc[f"shape{m}_{name or 'default'}"] = shape
    return desc


def render_mitsuba(scene: Scene, camera: Camera, spp: int, seed: int) -> np.ndarray:
    """Mitsuba 3's `path` render of scene: (H, W, 3) float32 linear RGB."""
    mi = load_mitsuba()
    with tempfile.TemporaryDirectory() as folder:
        loaded = mi.load_dict(mitsuba_scene(scene, camera, spp, Path(folder)))
    return np.array(mi.render(loaded, spp=spp, seed=seed), dtype=np.float32)


def main(argv: list[str] | None = None) -> int:
    """Render an example scene with dpm `pt` and Mitsuba 3; write them side by side."""
    p = argparse.ArgumentParser(prog="python -m dpm.validation.mitsuba", description=main.__doc__)
    p.add_argument("scene", type=Path)
    p.add_argument("-o", "--output", type=Path, required=True, help="side-by-side PNG")
    p.add_argument("--spp", type=int, default=256)
    args = p.parse_args(argv)
    try:
        side_by_side(args.scene, args.output, args.spp)
    except InputError as exc:
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 2
    return 0


def side_by_side(path: Path, output: Path, spp: int) -> None:
    """Write dpm `pt` (left) and Mitsuba 3 `path` (right) renders of a scene as one PNG."""
    import imageio.v3 as iio

    from dpm import load_scene
    from dpm.io import linear_to_srgb8
    from dpm.renderer import RenderOptions, render

    load_mitsuba()  # before the dpm render: a missing Mitsuba fails at once
    scene = load_scene(path)
    ours = render(scene, RenderOptions(method="pt", spp=spp)).image
    theirs = render_mitsuba(scene, scene.camera, spp, seed=0)
    gap = np.ones((ours.shape[0], 4, 3), np.float32)
    iio.imwrite(output, linear_to_srgb8(np.concatenate([ours, gap, theirs], axis=1)))
    print(f"wrote {output}: dpm pt (left), Mitsuba 3 path (right), {spp} spp")


if __name__ == "__main__":
    sys.exit(main())
