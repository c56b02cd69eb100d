"""`auto`'s caustics through the denoiser against caustics added after it, at equal passes.

    python benchmarks/caustic_denoising.py [--passes 1 2 4 16] [--seeds 1 2] [--set examples]

`auto` sends the caustic image through OIDN with the path-traced one, and `restore_certain`
gives back each pixel the denoiser moved by more than the pixel's standard error (the
caustic's from its photon count). The alternative it replaced denoised the path-traced part
alone and added the caustics after. Both come from the same render (same passes, photons and
samples: `Passes.finish` is wrapped to compose the second image too), so the ratio is free of
timing and sampling noise. Per scene, at each pass count P (`--spp P --photons P·4·pixels`,
the paths per pass of a `--time` render) and seed, RMSE against a reference:

- examples (where the choice was made): the equal-time references
  (results/equal_time/NAME-WxH-reference.exr: pt-nocaustic + the PPM caustic reference);
- unseen (reported, never chosen on): the Mitsuba 3 references of results/unseen at their
  size (a scaled copy against its scale-1 twin's, as `equal_time_unseen.py`).

Writes results/caustic_denoising/SET.json and results/caustic_denoising.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from equal_time_unseen import scoring_reference  # noqa: E402
from make_unseen import CONTROLS, UNSEEN, unseen_scenes  # noqa: E402

from common import RESULTS, SCENES, cpu, markdown_table  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import read_exr  # noqa: E402
from dpm.methods import auto  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.options import RenderOptions  # noqa: E402
from dpm.renderer import render  # noqa: E402
from dpm.scene import Scene  # noqa: E402

OUT = RESULTS / "caustic_denoising"
TABLE = RESULTS / "caustic_denoising.md"
EXAMPLES = ("dragon", "glass_egg", "pool1", "pool2", "red_wine", "ring", "torus")


def added_after(passes: auto.Passes) -> np.ndarray:
    """(H, W, 3) float32: the render's image with the caustics added after the denoiser,
    which sees the path-traced part alone (the light seen known well added after too)."""
    h, w = passes.h, passes.w
    caustic, _ = passes.caustics()
    seen, error, after = passes.light_seen()
    image = (passes.paths.mean() + np.where(after, 0, seen)).astype(np.float32).reshape(h, w, 3)
    total = np.hypot(passes.paths.standard_error(), np.where(after[:, 0], 0, error))
    image = auto.restore_certain(image, auto.denoise(image, *passes.guides()), total.reshape(h, w))
    image += np.where(after, seen, 0).astype(np.float32).reshape(h, w, 3)
    return image + caustic.astype(np.float32).reshape(h, w, 3)


def scenes(which: str) -> list[tuple[str, Scene, Path]]:
    """(name, scene, reference EXR) of the set."""
    if which == "examples":
        refs = RESULTS / "equal_time"
        return [(n, load_scene(SCENES / f"{n}.obj"), next(refs.glob(f"{n}-*-reference.exr")))
                for n in EXAMPLES]  # fmt: skip
    paths = {p.stem: p for p in unseen_scenes()}
    out = []
    for name in UNSEEN:
        if name not in CONTROLS:
            scene = load_scene(paths[name])
            out.append((name, scene, scoring_reference(name, scene.camera.width)[2]))
    return out


def run(which: str, pass_counts: list[int], seeds: list[int]) -> dict:
    """Both images' RMSE per scene, pass count and seed."""
    composed = {}
    finish = auto.Passes.finish

    def both(self: auto.Passes) -> np.ndarray:
        composed["after"] = added_after(self)
        return finish(self)

    auto.Passes.finish = both
    rows = []
    try:
        for name, scene, ref_path in scenes(which):
            ref = read_exr(ref_path)
            h, w = ref.shape[:2]
            for p in pass_counts:
                through, after = [], []
                for seed in seeds:
                    options = RenderOptions(width=w, height=h, spp=p, photons=p * 4 * w * h,
                                            seed=seed, progress=False)  # fmt: skip
                    image = render(scene, options).image
                    through.append(rmse(image, ref))
                    after.append(rmse(composed["after"], ref))
                r = {
                    "scene": name,
                    "size": f"{w}x{h}",
                    "passes": p,
                    "through": float(np.mean(through)),
                    "after": float(np.mean(after)),
                }
                rows.append(r)
                ratio = r["through"] / r["after"]
                print(f"{which} {name} {p} passes: through {r['through']:.4f} after "
                      f"{r['after']:.4f} ratio {ratio:.3f}", flush=True)  # fmt: skip
    finally:
        auto.Passes.finish = finish
    return {"set": which, "seeds": seeds, "cpu": cpu(), "date": str(datetime.date.today()),
            "rows": rows}  # fmt: skip


def report(records: list[dict]) -> str:
    """The Markdown report: a table per set, the geometric mean of the ratios per pass count."""
    lines = [
        "# `auto`: caustics through the denoiser vs added after it, at equal passes",
        "",
        "Made by `python benchmarks/caustic_denoising.py --set examples` and `--set unseen`",
        "(see its docstring): the same render composed both ways; RMSE against the reference,",
        "the mean over the seeds; ratio = through / after (below 1: the denoised caustics win).",
        "",
    ]
    for r in records:
        lines += [f"## {r['set']} (seeds {r['seeds']}; {r['cpu']}; {r['date']})", ""]
        head = ["scene", "W x H", "passes", "after RMSE", "through RMSE", "ratio"]
        rows = [
            [x["scene"], x["size"], str(x["passes"]), f"{x['after']:.4f}", f"{x['through']:.4f}",
             f"{x['through'] / x['after']:.3f}"]
            for x in r["rows"]
        ]  # fmt: skip
        lines += [*markdown_table(head, rows), ""]
        for p in sorted({x["passes"] for x in r["rows"]}):
            q = np.array([x["through"] / x["after"] for x in r["rows"] if x["passes"] == p])
            lines.append(f"- {p} passes: geometric mean {float(np.exp(np.log(q).mean())):.3f}, "
                         f"range {q.min():.3f}-{q.max():.3f} over {len(q)} scenes")  # fmt: skip
        lines.append("")
    return "\n".join(lines)


def main() -> None:
    """Run one set and rebuild the report from every set's record."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--set", choices=["examples", "unseen"], default="examples")
    p.add_argument("--passes", type=int, nargs="+", default=[1, 2, 4, 16])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    args = p.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    record = run(args.set, args.passes, args.seeds)
    (OUT / f"{args.set}.json").write_text(json.dumps(record, indent=1) + "\n")
    records = [json.loads((OUT / f"{s}.json").read_text()) for s in ("examples", "unseen")
               if (OUT / f"{s}.json").exists()]  # fmt: skip
    TABLE.write_text(report(records))


if __name__ == "__main__":
    main()
