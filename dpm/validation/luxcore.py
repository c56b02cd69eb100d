"""Converter from a dpm scene to LuxCoreRender (pyluxcore), the second peer renderer.

What a Blender user who wants caustics would pick: the PATHCPU engine with its PhotonGI caustic
cache (the indirect cache off: the comparison is about caustics). The conversion mirrors
`dpm.validation.mitsuba`:

- one mesh per material (flat-shaded, unshared vertices, winding kept); DIFFUSE as `matte`
  (kd = Kd), MIRROR as `mirror` (kr = Ks; both two-sided in LuxCore, as in dpm), DIELECTRIC
  as `glass` (kr = 1, kt = Tf: applied at every refraction, as Mitsuba's
  `specular_transmittance`; interiorior = Ni on the back side, exteriorior = 1 on the front);
- an emitter (Ke > 0) is its material (Kd behind it) with `emission` = Ke, gain 1, power and
  efficiency 0 (so the value is radiance in W m⁻² sr⁻¹, not a normalised power), from the
  front (counter-clockwise) face only, as LuxCore's triangle lights are one-sided;
- the pinhole camera with an explicit screen window: LuxCore's `fieldofview` spans the
  window's extent 1, which by default is the image's longer side; the window
  [-1, 1] x [-(H+2)/W, (H-2)/W] makes it the horizontal field of view and undoes LuxCore's
  one-row vertical offset (its raster y is H - filmY - 1). The film's rows run bottom-up and
  are flipped back;
- a one-pixel box filter, the linear RGB output (no tone mapping, no gamma), path depth 64
  for every kind of bounce (Mitsuba's `path` is unbounded; Russian roulette ends paths), no
  variance clamping, a fixed seed, one render thread per CPU.

PhotonGI caustic cache settings are LuxCore's and BlendLuxCore's defaults (100 000 photons per
pass, 10° normal angle, rebuilt every 8 samples per pixel, the radius divided by (pass + 1) to
the power 0.02 at each rebuild), except two lengths, which those give in metres and which here
follow the view: the initial lookup radius is RADIUS_FOOTPRINTS pixel width at the camera's
target, the minimum radius 1/MIN_RADIUS_DIVISOR of it (0.075 m and 0.003 m in BlendLuxCore;
at several pixel widths each lookup gathers thousands of photons and eye samples crawl).
Photon paths get the same depth as eye paths. The cache is only switched on where the scene has
a mirror or dielectric: without one, every rebuild traces its full 20 million photon paths for
nothing (90 s on 2 cores).

Costs on 2 cores: the cache's first build (visibility particles, then the first pass) takes
6-8 s on the example caustic scenes before any sample, each rebuild 3-6 s, so PATHCPU with the
cache reaches about 80 spp in 45 s whatever the resolution. A time-boxed render stops before a
rebuild that would not end within the budget (Stop() waits for it). LuxCore seeds its photon
tracing from a fixed base, not `renderengine.seed`; renders are not reproducible anyway
(threads share the work).

pyluxcore swaps the process's malloc for TBB's (its extension links libtbbmalloc_proxy); after
that, importing SciPy, Numba, JAX, Dr.Jit or OpenEXR aborts the process. `render_luxcore` thus
renders in a child process; `render_in_process` is for processes that imported all else first.

As a module it renders time-boxed in a fresh process, the budget counted from the process
start (interpreter, pyluxcore import and conversion included):

    python -m dpm.validation.luxcore SCENE.obj --width 64 --height 64 --time 10 -o out.npy

pyluxcore comes with the bench extra (`pip install -e ".[bench]"`); it is imported only inside
the functions that need it, and its absence is a one-line InputError.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import io
import json
import math
import os
import pickle
import subprocess
import sys
import tempfile
import time
from collections import deque
from pathlib import Path

import numpy as np

from dpm.camera import Camera
from dpm.clock import process_started
from dpm.errors import InputError
from dpm.scene import DIELECTRIC, MIRROR, THIN, Scene

MAX_DEPTH = 64  # eye and photon path depth ("unbounded" in Mitsuba; RR ends paths)
RADIUS_FOOTPRINTS = 1.0  # initial caustic lookup radius, in pixel widths at the camera target
MIN_RADIUS_DIVISOR = 25.0  # initial / minimum caustic radius (BlendLuxCore: 0.075 / 0.003)
CAUSTIC_PHOTONS = 100_000  # caustic photons stored per cache pass (LuxCore's default)
PHOTON_MAXCOUNT = 20_000_000  # photon paths traced at most per pass (BlendLuxCore's default)
UPDATE_SPP = 8  # samples per pixel between caustic cache rebuilds (LuxCore's default)
RADIUS_REDUCTION = 0.96  # LuxCore's default
NORMAL_ANGLE = 10.0  # degrees, LuxCore's default
POLL = 0.02  # seconds between checks of a running render
STOP_RESERVE = 0.3  # seconds kept for stopping, reading the film and writing the output
GUIDE_OUTPUTS = ("RGB", "ALBEDO", "AVG_SHADING_NORMAL")  # film outputs read with guides

LOG: deque[str] = deque(maxlen=400)  # LuxCore's latest log lines
_initialised = False


def load_pyluxcore():
    """The `pyluxcore` module, initialised with its log going to LOG; InputError when absent."""
    global _initialised
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # it prints the libraries it loads
            import pyluxcore
    except ImportError:
        raise InputError(
            "pyluxcore is not installed: pip install -e '.[bench]' (or pip install pyluxcore)"
        ) from None
    if not _initialised:
        pyluxcore.Init(lambda line: LOG.append(line.rstrip()))
        # A Python log handler still set at interpreter exit aborts the process.
        atexit.register(pyluxcore.SetLogHandler, None)
        _initialised = True
    return pyluxcore


def _floats(value: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(value).ravel()]


def caustic_radii(camera: Camera, radius: float | None = None) -> tuple[float, float]:
    """(initial, minimum) PhotonGI caustic lookup radius in scene units: `radius` or
    RADIUS_FOOTPRINTS pixel widths at the camera target, and that over MIN_RADIUS_DIVISOR."""
    if radius is None:
        width = float(camera.footprint(np.asarray(camera.target)[None])[0])
        radius = RADIUS_FOOTPRINTS * width
    if not (radius > 0 and math.isfinite(radius)):
        raise InputError(f"caustic radius must be a positive length, not {radius}")
    return radius, radius / MIN_RADIUS_DIVISOR


def meshes(scene: Scene) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Per material index: (vertices (3T, 3) float32, triangles (T, 3) uint32) of its faces."""
    out = {}
    for m in range(len(scene.materials.names)):
        triangles = scene.triangles[scene.material == m]
        if len(triangles):
            points = np.ascontiguousarray(triangles.reshape(-1, 3), dtype=np.float32)
            faces = np.arange(len(points), dtype=np.uint32).reshape(-1, 3)
            out[m] = (points, faces)
    return out


def scene_properties(scene: Scene, camera: Camera) -> dict[str, object]:
    """LuxCore scene properties (materials, objects `obj<m>` on meshes `mesh<m>`, camera)."""
    mats = scene.materials
    if mats.textures is not None:
        raise InputError(f"{scene.path}: textured materials are not converted to LuxCore")
    props: dict[str, object] = {}
    for m in meshes(scene):
        key = f"scene.materials.mat{m}"
        if mats.kind[m] == MIRROR:
            props |= {f"{key}.type": "mirror", f"{key}.kr": _floats(mats.specular[m])}
        elif mats.kind[m] in (DIELECTRIC, THIN):
            props |= {
                f"{key}.type": "glass" if mats.kind[m] == DIELECTRIC else "archglass",
                f"{key}.kr": [1.0, 1.0, 1.0],
                f"{key}.kt": _floats(mats.transmittance[m]),
                f"{key}.interiorior": float(mats.ior[m]),
                f"{key}.exteriorior": 1.0,
            }
        else:
            props |= {f"{key}.type": "matte", f"{key}.kd": _floats(mats.albedo[m])}
        if mats.emission[m].max() > 0:
            props |= {
                f"{key}.emission": _floats(mats.emission[m]),
                f"{key}.emission.gain": [1.0, 1.0, 1.0],
                f"{key}.emission.power": 0.0,
                f"{key}.emission.efficiency": 0.0,
                f"{key}.emission.theta": 90.0,
            }
        props[f"scene.objects.obj{m}.shape"] = f"mesh{m}"
        props[f"scene.objects.obj{m}.material"] = f"mat{m}"
    w, h = camera.width, camera.height
    props |= {
        "scene.camera.type": "perspective",
        "scene.camera.lookat.orig": _floats(camera.origin),
        "scene.camera.lookat.target": _floats(camera.target),
        "scene.camera.up": _floats(camera.up),
        "scene.camera.fieldofview": float(camera.fov),
        "scene.camera.screenwindow": [-1.0, 1.0, -(h + 2) / w, (h - 2) / w],
    }
    return props


def config_properties(
    camera: Camera,
    seed: int = 0,
    spp: int | None = None,
    caustics: bool = True,
    threads: int | None = None,
    caustic_radius: float | None = None,
) -> dict[str, object]:
    """LuxCore render configuration: PATHCPU (+ PhotonGI caustic cache), film, halt, seed."""
    props: dict[str, object] = {
        "renderengine.type": "PATHCPU",
        "renderengine.seed": int(seed) + 1,  # LuxCore's seeds start at 1
        "native.threads.count": int(threads or _cpu_count()),
        "sampler.type": "SOBOL",
        "lightstrategy.type": "LOG_POWER",
        "path.pathdepth.total": MAX_DEPTH,
        "path.pathdepth.diffuse": MAX_DEPTH,
        "path.pathdepth.glossy": MAX_DEPTH,
        "path.pathdepth.specular": MAX_DEPTH,
        "path.hybridbackforward.enable": False,
        "path.clamping.variance.maxvalue": 0.0,
        "film.width": camera.width,
        "film.height": camera.height,
        "film.filter.type": "BOX",
        "film.filter.width": 0.5,
        "film.opencl.enable": False,
        "film.imagepipelines.0.0.type": "TONEMAP_LINEAR",
        "film.imagepipelines.0.0.scale": 1.0,
    }
    if spp is not None:
        props["batch.haltspp"] = int(spp)
    if caustics:
        radius, min_radius = caustic_radii(camera, caustic_radius)
        props |= {
            "path.photongi.photon.maxcount": PHOTON_MAXCOUNT,
            "path.photongi.photon.maxdepth": MAX_DEPTH,
            "path.photongi.indirect.enabled": False,
            "path.photongi.caustic.enabled": True,
            "path.photongi.caustic.maxsize": CAUSTIC_PHOTONS,
            "path.photongi.caustic.lookup.radius": radius,
            "path.photongi.caustic.lookup.normalangle": NORMAL_ANGLE,
            "path.photongi.caustic.updatespp": UPDATE_SPP,
            "path.photongi.caustic.updatespp.radiusreduction": RADIUS_REDUCTION,
            "path.photongi.caustic.updatespp.minradius": min_radius,
        }
    return props


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _properties(lc, values: dict[str, object]):
    props = lc.Properties()
    for name, value in values.items():
        props.Set(lc.Property(name, value))
    return props


def luxcore_scene(scene: Scene, camera: Camera):
    """A `pyluxcore.Scene` of scene seen by camera (meshes from the triangle arrays)."""
    lc = load_pyluxcore()
    out = lc.Scene()
    for m, (points, faces) in meshes(scene).items():
        out.DefineMeshExt(f"mesh{m}", points, faces)
    out.Parse(_properties(lc, scene_properties(scene, camera)))
    return out


def _stat(stats, name: str, default: float = 0.0) -> float:
    return float(stats.Get(name).GetFloat()) if stats.IsDefined(name) else default


class _UpdateClock:
    """Predicts PhotonGI caustic cache rebuilds from a running render's sample count.

    LuxCore rebuilds the cache once the film's whole samples per pixel exceed the last
    rebuild's by UPDATE_SPP; no sample is taken meanwhile, and Stop() waits for a rebuild to
    end. So a time-boxed render stops before a rebuild that would not end in time. A rebuild's
    length is taken as the longest stall of the sample count seen so far, at first as the
    length of the start (visibility particles and the first cache: an overestimate).
    """

    def __init__(self, pixels: int, every: int, first_build: float, now: float) -> None:
        self.pixels, self.every = pixels, every  # rebuilt when spp exceeds the last by `every`
        self.rebuild = first_build  # seconds a rebuild is expected to take
        self.last_spp = 0  # whole spp at the last rebuild
        self.samples, self.moved = 0.0, now  # last sample count, and when it last grew
        self.rate = 0.0  # spp per second while sampling

    def observe(self, samples: float, now: float) -> None:
        """Record the sample count read at `now`."""
        if samples > self.samples:
            stalled = now - self.moved
            spp = int(self.samples // self.pixels)
            if stalled > 5 * POLL and self.samples > 0 and spp >= self.last_spp + self.every:
                # a rebuild just ended
                self.rebuild = max(self.rebuild if self.last_spp else 0.0, stalled)
                self.last_spp = spp
            elif stalled > 0:
                rate = (samples - self.samples) / self.pixels / stalled
                self.rate = rate if self.rate == 0 else 0.7 * self.rate + 0.3 * rate
            self.samples, self.moved = samples, now

    def must_stop(self, now: float, stop_at: float) -> bool:
        """Whether a rebuild is about to start that would not end before `stop_at` (not
        while one seems under way: Stop() would wait for it anyway)."""
        if self.rate <= 0 or now + self.rebuild + POLL < stop_at or now - self.moved > 5 * POLL:
            return False
        next_spp = self.last_spp + self.every + 1
        return (next_spp - self.samples / self.pixels) / self.rate < 3 * POLL


def has_specular(scene: Scene) -> bool:
    """Whether some triangle is a mirror or dielectric (else a caustic cache has nothing)."""
    used = np.unique(scene.material)
    return bool(np.isin(scene.materials.kind[used], (MIRROR, DIELECTRIC, THIN)).any())


def render_in_process(
    scene: Scene,
    camera: Camera,
    spp: int | None = None,
    seed: int = 0,
    caustics: bool = True,
    threads: int | None = None,
    caustic_radius: float | None = None,
    deadline: float | None = None,
    properties: dict[str, object] | None = None,
    guides: bool = False,
) -> tuple[np.ndarray, dict]:
    """LuxCore render in this process: ((H, W, 3) float32 linear RGB radiance, stats); with
    `guides`, (H, W, 9): radiance, albedo and average shading normal (the denoiser's inputs).

    It stops at `spp` samples per pixel or by `deadline` (a `time.monotonic()` value),
    whichever comes first, but not before one sample per pixel (as a time-boxed Mitsuba
    render takes at least one batch: a black image is no render); the start (the caustic
    cache's first build) cannot be cut short, so a short deadline is overrun.
    The caustic cache is used only where the scene has a mirror or dielectric. `properties`
    override or add LuxCore render settings. Importing pyluxcore swaps the process's malloc
    for TBB's, after which loading many extension modules (SciPy, Numba, JAX, Dr.Jit,
    OpenEXR) aborts with "free(): invalid pointer": import everything else first, or use
    `render_luxcore` (a child process).
    """
    called = time.monotonic()
    if spp is None and deadline is None:
        raise InputError("a LuxCore render needs a number of samples per pixel or a deadline")
    stop_at = math.inf if deadline is None else deadline
    caustics = caustics and has_specular(scene)
    lc = load_pyluxcore()
    config = config_properties(camera, seed, spp, caustics, threads, caustic_radius)
    if guides:
        config |= {
            f"film.outputs.{i}.{key}": value
            for i, kind in enumerate(GUIDE_OUTPUTS)
            for key, value in (("type", kind), ("filename", f"{kind}.exr"))
        }
    config |= properties or {}
    render_config = lc.RenderConfig(_properties(lc, config), luxcore_scene(scene, camera))
    session = lc.RenderSession(render_config)
    w, h = camera.width, camera.height
    converted = time.monotonic()
    session.Start()
    started = time.monotonic()
    every = int(config.get("path.photongi.caustic.updatespp", 0)) if caustics else 0
    clock = _UpdateClock(w * h, every, started - converted, started)
    try:
        while not session.HasDone() and (spp is None or clock.samples < spp * w * h):
            now = time.monotonic()
            late = now + POLL >= stop_at or (every and clock.must_stop(now, stop_at))
            if late and clock.samples >= w * h:
                break
            time.sleep(POLL)
            session.UpdateStats()
            count = _stat(session.GetStats(), "stats.renderengine.total.samplecount")
            clock.observe(count, time.monotonic())
    finally:
        session.Stop()
    stopped = time.monotonic()
    planes = []
    for kind in GUIDE_OUTPUTS if guides else GUIDE_OUTPUTS[:1]:
        film = np.zeros((h, w, 3), np.float32)
        session.GetFilm().GetOutputFloat(getattr(lc.FilmOutputType, kind), film)
        planes.append(film[::-1])  # film rows run bottom-up
    image = np.ascontiguousarray(np.concatenate(planes, axis=-1))
    samples = _stat(session.GetStats(), "stats.renderengine.total.samplecount")
    stats = {
        "renderer": f"LuxCoreRender {lc.Version()} PATHCPU"
        + (" + PhotonGI caustic cache" if caustics else ""),
        "spp": samples / (w * h),
        "threads": config["native.threads.count"],
        "seconds_convert": converted - called,
        "seconds_start": started - converted,  # preprocessing, first caustic cache included
        "seconds_render": stopped - started,
        "seconds": stopped - called,
    }
    if caustics:
        stats["caustic_radius"] = config["path.photongi.caustic.lookup.radius"]
        stats["caustic_min_radius"] = config["path.photongi.caustic.updatespp.minradius"]
        stats["caustic_rebuild_seconds"] = clock.rebuild if clock.last_spp else None
    return image, stats


def render_luxcore(
    scene: Scene,
    camera: Camera,
    seconds: float | None = None,
    spp: int | None = None,
    seed: int = 0,
    caustics: bool = True,
    threads: int | None = None,
    caustic_radius: float | None = None,
    properties: dict[str, object] | None = None,
) -> tuple[np.ndarray, dict]:
    """LuxCore PATHCPU (+ PhotonGI caustic cache unless `caustics` is False) render of scene
    in a child process: ((H, W, 3) float32 linear RGB radiance, stats). It stops at `spp`
    samples per pixel or after `seconds` counted from this call (the child's start, pyluxcore
    import and conversion included), whichever comes first; see `render_in_process`."""
    called = time.monotonic()
    if seconds is None and spp is None:
        raise InputError("render_luxcore needs seconds and/or spp")
    job = {
        "scene": scene, "camera": camera, "spp": spp, "seed": seed, "caustics": caustics,
        "threads": threads, "caustic_radius": caustic_radius, "properties": properties,
        "deadline": None if seconds is None else called + seconds - STOP_RESERVE,
    }  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="dpm-luxcore-") as folder:
        job_path, out = Path(folder) / "job.pickle", Path(folder) / "image.npy"
        with open(job_path, "wb") as f:
            pickle.dump(job, f)
        command = [sys.executable, "-m", "dpm.validation.luxcore", "--job", str(job_path)]
        done = subprocess.run([*command, "-o", str(out)], capture_output=True, text=True)
        if done.returncode != 0 or not out.exists():
            why = (done.stderr.strip() or done.stdout.strip() or "no output").splitlines()[-1]
            raise InputError(f"LuxCore child process failed (exit {done.returncode}): {why}")
        image = np.load(out)
    stats = json.loads(done.stdout.strip().splitlines()[-1])
    stats["seconds_call"] = time.monotonic() - called
    return image, stats


def main(argv: list[str] | None = None) -> int:
    """Render a dpm scene with LuxCore within a whole-process time budget (or to an spp)."""
    started = process_started()
    p = argparse.ArgumentParser(prog="python -m dpm.validation.luxcore", description=main.__doc__)
    p.add_argument("scene", type=Path, nargs="?", help="a dpm scene (.obj)")
    p.add_argument("-o", "--output", type=Path, required=True, help=".npy (or .exr, .png)")
    p.add_argument("--width", type=int, help="pixels (default: the scene's camera)")
    p.add_argument("--height", type=int, help="pixels (default: the scene's camera)")
    p.add_argument("--time", type=float, help="seconds of wall time from the process start")
    p.add_argument("--spp", type=int, help="samples per pixel (stops earlier if reached)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, help="render threads (default: one per CPU)")
    p.add_argument("--no-caustic-cache", action="store_true", help="plain PATHCPU")
    p.add_argument("--caustic-radius", type=float, help="initial lookup radius (scene units)")
    p.add_argument("--denoised", type=Path, help="also write the OIDN-denoised image here")
    p.add_argument(
        "--clean-guides-from", type=float, metavar="SPP",
        help="tell OIDN the guides are noise-free (cleanAux) from this many samples per pixel"
        " (default: never)",
    )  # fmt: skip
    p.add_argument(
        "--reserve",
        type=float,
        default=STOP_RESERVE,
        help="seconds of --time kept for the end (stop, denoise, write, exit)",
    )
    p.add_argument("--job", type=Path, help=argparse.SUPPRESS)  # render_luxcore's child
    args = p.parse_args(argv)
    if args.job is None and (args.scene is None or (args.time is None and args.spp is None)):
        p.error("give a scene and --time and/or --spp")
    try:
        # Before pyluxcore, which swaps malloc: see render_in_process.
        from dpm.denoise import denoise
        from dpm.io import write_image
        from dpm.scene import load_scene

        if args.job is not None:
            with open(args.job, "rb") as f:
                job = pickle.load(f)
        else:
            scene = load_scene(args.scene)
            job = {
                "scene": scene, "camera": scene.camera.with_resolution(args.width, args.height),
                "spp": args.spp, "seed": args.seed, "caustics": not args.no_caustic_cache,
                "threads": args.threads, "caustic_radius": args.caustic_radius,
                "deadline": None if args.time is None else started + args.time - args.reserve,
                "guides": args.denoised is not None,
            }  # fmt: skip
        image, stats = render_in_process(**job)
        stats["seconds_rendered"] = time.monotonic() - started
        outputs = [(args.output, image[..., :3])]
        if args.denoised is not None:
            clean = args.clean_guides_from is not None and stats["spp"] >= args.clean_guides_from
            outputs.append(
                (args.denoised, denoise(image[..., :3], image[..., 3:6], image[..., 6:], clean))
            )
        for path, picture in outputs:
            if path.suffix.lower() == ".npy":
                np.save(path, picture)
            else:
                write_image(path, picture)
    except InputError as exc:
        print(f"{p.prog}: error: {exc}", file=sys.stderr)
        return 2
    stats["seconds_process"] = time.monotonic() - started
    print(json.dumps(stats))
    return 0


if __name__ == "__main__":
    sys.exit(main())
