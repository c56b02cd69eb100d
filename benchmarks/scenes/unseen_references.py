"""References for the unseen-scene set (`make_unseen.py`): Mitsuba 3 full images and PPM caustics.

    python benchmarks/scenes/unseen_references.py [NAME ...] [--width 128] [--spp 4096]
        [--paths 20000000] [--caustic-spp 64] [--only mitsuba|caustic] [--variant V] [--out DIR]

Per scene (default: all of them, written first where missing), at --width pixels wide and the
height of the scene's own aspect (W x H below), into benchmarks/results/unseen/:

- NAME-WxH-mitsuba.exr + .json: Mitsuba 3 `path` (its defaults: unbounded depth, Russian
  roulette from depth 5, as `benchmarks/equal_time.py` runs it), converted by the project's
  `dpm.validation.mitsuba.mitsuba_scene`. Two independent halves of --spp samples per pixel
  each (disjoint seeds); the EXR is their mean. The JSON holds spp per half, seconds, the
  variant, and the expected RMSE of the mean: with halves A and B of per-pixel variance s^2
  each, E[(A - B)^2] = 2 s^2 and Var((A + B) / 2) = s^2 / 2 = E[(A - B)^2] / 4, so
      noise = RMSE(A, B) / 2
  (over all pixels and channels, `noise_rgb`, as `dpm.metrics.rmse` scores; and on Rec. 709
  luminance, `noise_luminance`).
- NAME-WxH-caustic.exr + .json: the caustic radiance the camera sees (light paths L S+ D
  seen through any specular chain), per pixel: --caustic-spp visible points per pixel and
  --paths guided photon paths of PPM in two independent halves (`dpm.estimators.reference`,
  as `benchmarks/hybrid.py`'s `caustic_reference`). Its initial radius is half the median
  pixel footprint at the visible points (scale and resolution invariant, unlike a fraction of
  the scene's bounding box, which the huge floor and far wall make 1000 units long). The
  JSON's `noise` (luminance) adds the photons' share (the halves' squared difference over 4)
  and the pixel sampling's (the variance of a pixel's points over their number), an upper
  bound. Diffuse-only scenes get a zero image and zero noise without tracing anything.

Resumable: a result whose JSON says it has at least the asked spp (or paths, at the same
caustic spp) is skipped; Mitsuba saves each half every chunk of about 2^20 samples, PPM each
half every 30 s, under benchmarks/results/unseen/partial/ (git-ignored), and a run that is
stopped picks up from there.

Mitsuba's variant: llvm_ad_rgb where a usable libLLVM exists, else scalar_rgb (about 3.5x
slower; a printed line says so). On this AVX-512 host (Dr.Jit 1.x of Mitsuba 3.9) LLVM 14
does not load, and LLVM 15 and 16 abort with "LLVM ERROR: Cannot select: ... fminimum";
LLVM 19 works: `apt-get install -y libllvm19` (Debian 12 main has it). The newest
libLLVM*.so* found under /usr/lib (or DRJIT_LIBLLVM_PATH, if set) is handed to Dr.Jit via
DRJIT_LIBLLVM_PATH, and a one-sample render in a child process checks it before use.
--variant forces one (e.g. cuda_ad_rgb on a GPU machine).
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from make_unseen import SCENES_DIR, UNSEEN, unseen_scenes  # noqa: E402

from dpm import load_scene  # noqa: E402
from dpm.camera import Camera  # noqa: E402
from dpm.density.base import luminance  # noqa: E402
from dpm.estimators.reference import ppm_reference  # noqa: E402
from dpm.io import write_image, write_json  # noqa: E402
from dpm.methods.auto import has_specular  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.scene import Scene  # noqa: E402
from dpm.tracer import build_bvh, trace_visible_points  # noqa: E402
from dpm.validation.mitsuba import mitsuba_scene  # noqa: E402

OUT = Path(__file__).parents[1] / "results" / "unseen"
SPP = 4096  # Mitsuba samples per pixel of each half
PATHS = 20_000_000  # guided photon paths of the caustic reference, both halves together
CAUSTIC_SPP = 64  # visible points per pixel of the caustic reference (as benchmarks/hybrid.py)
PHOTONS_PER_PASS = 1_000_000
CHUNK_SAMPLES = 2**20  # Mitsuba samples per call (and per checkpoint) of a half
HALF_SEEDS = (1_000_000, 2_000_000)  # a chunk's seed: its half's base + the spp done before it
VISIBLE_SEED = 1001
PPM_SEED = 7

MITSUBA_CHILD = r"""
import json, sys, time
from pathlib import Path
import numpy as np
import mitsuba as mi
desc_path, variant, folder, spp, chunk = sys.argv[1:6]
spp, chunk, folder = int(spp), int(chunk), Path(folder)
seeds = [int(s) for s in sys.argv[6].split(",")]
mi.set_variant(variant)
desc = json.loads(Path(desc_path).read_text())
s = desc["sensor"]
s["to_world"] = mi.ScalarTransform4f().look_at(**s.pop("look_at"))
scene = mi.load_dict(desc)
shown = time.perf_counter()
for half, base in enumerate(seeds):
    path = folder / f"half{half}.npz"
    if path.exists():
        z = np.load(path)
        total, done, seconds, bad = z["sum"], int(z["spp"]), float(z["seconds"]), int(z["bad"])
    else:
        total, done, seconds, bad = None, 0, 0.0, 0
    while done < spp:
        n = min(chunk, spp - done)
        start = time.perf_counter()
        image = np.array(mi.render(scene, spp=n, seed=base + done), dtype=np.float64)
        seconds += time.perf_counter() - start
        finite = np.isfinite(image)
        bad += int((~finite).sum())
        image = np.where(finite, image, 0.0) * n
        total = image if total is None else total + image
        done += n
        tmp = folder / f"half{half}.tmp.npz"
        np.savez(tmp, sum=total, spp=done, seconds=seconds, bad=bad)
        tmp.replace(path)
        if done == spp or time.perf_counter() - shown > 15:
            print(f"  mitsuba half {half}: {done}/{spp} spp, {seconds:.1f} s", flush=True)
            shown = time.perf_counter()
"""

PROBE = (
    "import mitsuba as mi, sys; mi.set_variant(sys.argv[1]); "
    "d = mi.cornell_box(); d['sensor']['film']['width'] = d['sensor']['film']['height'] = 8; "
    "mi.render(mi.load_dict(d), spp=1)"
)


def llvm_library() -> str | None:
    """Path of the newest libLLVM shared library found (DRJIT_LIBLLVM_PATH wins), or None."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    found = []
    for pattern in ("/usr/lib/*/libLLVM*.so*", "/usr/lib/llvm-*/lib/libLLVM*.so*",
                    "/usr/local/lib/libLLVM*.so*", "/usr/lib/libLLVM*.so*"):  # fmt: skip
        for path in glob.glob(pattern):
            match = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", Path(path).name)
            if match:
                found.append((int(match.group(1)), path))
    return max(found)[1] if found else None


def mitsuba_variant(forced: str | None) -> tuple[str, dict[str, str]]:
    """(variant, environment for the child): llvm_ad_rgb with the newest libLLVM when a probe
    render succeeds, else scalar_rgb; `forced` is taken as it is."""
    env = dict(os.environ)
    library = llvm_library()
    if library:
        env["DRJIT_LIBLLVM_PATH"] = library
    if forced:
        return forced, env
    if library:
        probe = subprocess.run([sys.executable, "-c", PROBE, "llvm_ad_rgb"], env=env,
                               capture_output=True, text=True)  # fmt: skip
        if probe.returncode == 0:
            print(f"Mitsuba variant llvm_ad_rgb with {library}", flush=True)
            return "llvm_ad_rgb", env
        why = (probe.stderr.strip().splitlines() or ["?"])[0][:120]
        print(f"llvm_ad_rgb failed with {library} ({why}); need a newer libLLVM (19 works) "
              "(apt-get install libllvm19): falling back to scalar_rgb", flush=True)  # fmt: skip
    else:
        print("no libLLVM found (apt-get install libllvm19): Mitsuba falls back to scalar_rgb",
              flush=True)  # fmt: skip
    return "scalar_rgb", env


def sized_camera(scene: Scene, width: int) -> Camera:
    """The scene's camera at `width` pixels wide and the height of its own aspect."""
    height = max(1, width * scene.camera.height // scene.camera.width)
    return scene.camera.with_resolution(width, height)


def done_at(sidecar: Path, key: str, value: int, extra: dict | None = None) -> bool:
    """Whether a result's JSON exists (with its EXR) and has sidecar[key] >= value and the
    `extra` fields equal."""
    if not (sidecar.exists() and sidecar.with_suffix(".exr").exists()):
        return False
    data = json.loads(sidecar.read_text())
    return data.get(key, -1) >= value and all(data.get(k) == v for k, v in (extra or {}).items())


def mitsuba_reference(
    scene: Scene, camera: Camera, spp: int, variant: str, env: dict[str, str], folder: Path
) -> tuple[np.ndarray, dict]:
    """(mean (H, W, 3) float32 linear RGB of two halves of `spp` samples per pixel each,
    record with its noise); checkpoints in `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        desc = mitsuba_scene(scene, camera, 1, Path(tmp))
        c = camera
        desc["sensor"]["look_at"] = {
            "origin": c.origin.tolist(), "target": c.target.tolist(), "up": c.up.tolist()
        }  # fmt: skip
        del desc["sensor"]["to_world"]
        desc["integrator"] = {"type": "path", "max_depth": -1}
        (Path(tmp) / "desc.json").write_text(json.dumps(desc))
        (Path(tmp) / "child.py").write_text(MITSUBA_CHILD)
        chunk = max(1, CHUNK_SAMPLES // (camera.width * camera.height))
        seeds = ",".join(str(s) for s in HALF_SEEDS)
        assert spp < HALF_SEEDS[1] - HALF_SEEDS[0], "halves' seeds would overlap"
        subprocess.run(
            [sys.executable, str(Path(tmp) / "child.py"), str(Path(tmp) / "desc.json"), variant,
             str(folder), str(spp), str(chunk), seeds],
            check=True, env=env,
        )  # fmt: skip
    halves, counts, seconds, bad = [], [], 0.0, 0
    for half in range(2):
        z = np.load(folder / f"half{half}.npz")
        counts.append(int(z["spp"]))  # more than asked where an earlier run asked for more
        halves.append(z["sum"] / counts[-1])
        seconds += float(z["seconds"])
        bad += int(z["bad"])
    assert min(counts) >= spp, counts
    a, b = halves
    mean = ((a + b) / 2).astype(np.float32)
    record = {
        "renderer": "Mitsuba 3 path (max_depth -1)", "variant": variant,
        "width": camera.width, "height": camera.height, "spp_per_half": min(counts),
        "spp_halves": counts, "seeds": list(HALF_SEEDS),
        "noise_rgb": rmse(a, b) / 2, "noise_luminance": rmse(luminance(a), luminance(b)) / 2,
        "noise_formula": "RMSE(A, B) / 2: Var((A + B) / 2) = E[(A - B)^2] / 4",
        "render_seconds": seconds, "seconds": time.perf_counter() - start,
        "nonfinite_samples_dropped": bad,
    }  # fmt: skip
    return mean, record


def footprint_radius(camera: Camera, position: np.ndarray) -> float:
    """Half the median pixel footprint (scene units) at visible points `position` (N, 3)."""
    distance = np.linalg.norm(position.astype(np.float64) - camera.origin, axis=1)
    pixel = 2.0 * np.tan(np.radians(camera.fov) / 2) / camera.width
    return 0.5 * float(np.median(distance)) * pixel


def caustic_reference(
    scene: Scene, camera: Camera, paths: int, spp: int, folder: Path
) -> tuple[np.ndarray, dict]:
    """((H, W, 3) float32 caustic radiance the camera sees per pixel, record with its expected
    RMSE (luminance)); the PPM halves' checkpoints in `folder`."""
    start = time.perf_counter()
    shape = (camera.height * camera.width, spp, 3)
    record: dict = {"renderer": "dpm PPM, guided, two halves", "width": camera.width,
                    "height": camera.height, "caustic_spp": spp}  # fmt: skip
    if not has_specular(scene):
        record.update(
            paths=paths,
            noise=0.0,
            photon_noise=0.0,
            sampling_noise=0.0,
            radius=0.0,
            caustic_photons=0,
            seconds=0.0,
            note="diffuse only: no caustics",
        )
        return np.zeros((camera.height, camera.width, 3), np.float32), record
    bvh = build_bvh(scene)
    points = trace_visible_points(scene, bvh, camera, spp, VISIBLE_SEED, (0, camera.height))
    radius = footprint_radius(camera, points.position[points.hit])
    ref = ppm_reference(
        scene, bvh, points, paths, radius, PHOTONS_PER_PASS, seed=PPM_SEED,
        checkpoint_dir=folder, progress=True,
    )  # fmt: skip
    seen = (points.throughput * ref.radiance).reshape(shape).astype(np.float64)
    halves = [luminance((points.throughput * h).reshape(shape).mean(axis=1)) for h in ref.halves]
    photons = (halves[0] - halves[1]) ** 2 / 4  # as benchmarks/hybrid.py's caustic_reference
    sampling = luminance(seen).var(axis=1, ddof=1) / spp
    image = seen.mean(axis=1).reshape(camera.height, camera.width, 3).astype(np.float32)
    record.update(
        paths=int(ref.n_paths), caustic_photons=int(ref.caustic_photons), radius=radius,
        noise=float(np.sqrt(np.mean(photons + sampling))),
        photon_noise=float(np.sqrt(np.mean(photons))),
        sampling_noise=float(np.sqrt(np.mean(sampling))),
        noise_formula="sqrt(mean over pixels of (halves' luminance difference)^2 / 4 + "
        "luminance variance of the pixel's points / caustic_spp)",
        seed=PPM_SEED, visible_seed=VISIBLE_SEED, seconds=time.perf_counter() - start,
    )  # fmt: skip
    return image, record


def run(name: str, args: argparse.Namespace, mitsuba: tuple[str, dict] | None) -> dict:
    """Build whichever of scene `name`'s two references is missing; return their seconds."""
    scene = load_scene(args.scenes / f"{name}.obj")
    camera = sized_camera(scene, args.width)
    stem = f"{name}-{camera.width}x{camera.height}"
    partial = args.out / "partial"
    times = {}
    if args.only in (None, "mitsuba"):
        sidecar = args.out / f"{stem}-mitsuba.json"
        if done_at(sidecar, "spp_per_half", args.spp):
            print(f"{stem}: Mitsuba reference exists", flush=True)
        else:
            variant, env = mitsuba if mitsuba else mitsuba_variant(args.variant)
            image, record = mitsuba_reference(
                scene, camera, args.spp, variant, env, partial / f"{stem}-mitsuba"
            )
            write_image(sidecar.with_suffix(".exr"), image)
            write_json(sidecar, record)
            times["mitsuba"] = record["seconds"]
            print(f"{stem}: Mitsuba {args.spp} spp x 2 in {record['seconds']:.1f} s, noise "
                  f"{record['noise_rgb']:.5f} (mean {image.mean():.4f})", flush=True)  # fmt: skip
    if args.only in (None, "caustic"):
        sidecar = args.out / f"{stem}-caustic.json"
        if done_at(sidecar, "paths", args.paths, {"caustic_spp": args.caustic_spp}):
            print(f"{stem}: caustic reference exists", flush=True)
        else:
            folder = partial / f"{stem}-caustic-{args.caustic_spp}spp"
            image, record = caustic_reference(scene, camera, args.paths, args.caustic_spp, folder)
            write_image(sidecar.with_suffix(".exr"), image)
            write_json(sidecar, record)
            times["caustic"] = record["seconds"]
            print(f"{stem}: caustic {record['paths']} paths in {record['seconds']:.1f} s, noise "
                  f"{record['noise']:.5f} (mean {image.mean():.4f})", flush=True)  # fmt: skip
    return times


def main() -> None:
    """Build the references of the scenes named (default: the whole unseen set)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("names", nargs="*", help=f"scenes (default: all): {', '.join(UNSEEN)}")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--spp", type=int, default=SPP, help="Mitsuba samples per pixel per half")
    p.add_argument("--paths", type=int, default=PATHS, help="guided photon paths (both halves)")
    p.add_argument("--caustic-spp", type=int, default=CAUSTIC_SPP)
    p.add_argument("--only", choices=["mitsuba", "caustic"])
    p.add_argument("--variant", help="Mitsuba variant (default: llvm_ad_rgb, else scalar_rgb)")
    p.add_argument("--scenes", type=Path, default=SCENES_DIR, help="folder of the scenes")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args()
    unknown = set(args.names) - set(UNSEEN)
    if unknown:
        p.error(f"unknown scene(s) {sorted(unknown)}")
    unseen_scenes(args.scenes)
    args.out.mkdir(parents=True, exist_ok=True)
    mitsuba = None if args.only == "caustic" else mitsuba_variant(args.variant)
    start = time.perf_counter()
    for name in args.names or list(UNSEEN):
        seconds = run(name, args, mitsuba)
        print(f"{name}: {seconds}", flush=True)
    print(f"all done in {time.perf_counter() - start:.1f} s", flush=True)


if __name__ == "__main__":
    main()
