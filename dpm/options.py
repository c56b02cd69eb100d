"""What to render: one options dataclass (plain data) from which the `dpm-render` flags,
their help and the scene sidecar's `[render]` keys are all derived.

Options a method reads only for itself (`--k`, `--radius`, ...) default to None and are
*scoped*: each method lists the ones it reads (`Method.options`), and a flag given to a
method that does not read it is an error (`dpm.methods.validate`). A sidecar's value for such
an option is a default for the methods that read it and is passed over by the others.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from typing import Any

COMPONENTS = ("full", "caustic")


def _option(
    default: Any,
    help: str,
    *,
    scoped: bool = False,
    sidecar: bool = True,
    default_text: str | None = None,
    metavar: str | None = None,
    supersedes: tuple[str, ...] = (),
) -> Any:
    """A RenderOptions field with its flag's help; default_text replaces a None default;
    when given as a flag it sets aside the sidecar's values of the fields in `supersedes`."""
    meta = {"help": help, "scoped": scoped, "sidecar": sidecar, "default_text": default_text,
            "metavar": metavar, "supersedes": supersedes}  # fmt: skip
    return field(default=default, metadata=meta)


@dataclass
class RenderOptions:
    """What to render; None means the default named in each field's help."""

    method: str = _option("auto", "rendering method")
    spp: int = _option(16, "samples per pixel")
    photons: int = _option(200_000, "emitted photon paths (photon methods)")
    seed: int = _option(0, "random seed (same seed, same image)")
    width: int | None = _option(None, "image width in pixels", default_text="the scene's camera")
    height: int | None = _option(None, "image height in pixels", default_text="the scene's camera")
    component: str = _option("full", "full image, or the caustics only")
    k: int | None = _option(
        None, "nearest photons per estimate", scoped=True,
        default_text="50; dpm and hybrid: the weight file's K",
    )  # fmt: skip
    radius: float | None = _option(
        None, "initial gather radius, scene units", scoped=True,
        default_text="each point's own, from its pixel width w and the distance r8 to its 8th"
        " nearest photon of the first pass: r8^(1/3)·w^(2/3), at most 4 pixel widths; auto: 2"
        " pixel widths",
    )  # fmt: skip
    time: float | None = _option(
        None, "render in passes until this many seconds of wall time (from the process start)",
        scoped=True, default_text="none: --spp paths per pixel", metavar="SECONDS",
    )  # fmt: skip
    photons_per_pass: int | None = _option(
        None,
        "emitted photon paths per pass",
        scoped=True,
        default_text="photons / 10; sppm: 0.25 per pixel; auto: planned",
    )
    checkpoint: Path | None = _option(
        None, "save the statistics here as it goes and resume from them", scoped=True,
        sidecar=False, default_text="none", metavar="FILE.npz",
    )  # fmt: skip
    weights: Path | None = _option(
        None, "network weights from dpm-train", scoped=True, sidecar=False,
        default_text="the shipped model for --k (auto: the shipped caustic filter)",
        metavar="FILE.msgpack", supersedes=("k",),
    )  # fmt: skip
    caustic_spp: int | None = _option(
        None, "estimate caustics at the first N samples per pixel only", scoped=True,
        default_text="every sample; hybrid: 1", metavar="N",
    )  # fmt: skip
    network: bool | None = _option(
        None, "auto's learned caustic filter (dpm/nn/caustic_net.py)", scoped=True,
        default_text="on where the plan keeps caustics and the network's cost fits the budget",
    )  # fmt: skip
    denoise: bool | None = _option(
        None, "Open Image Denoise with albedo and normal guides",
        default_text="on for auto and hybrid",
    )  # fmt: skip
    progress: bool = field(default=True, metadata={"cli": False})  # progress bars


def cli_fields() -> list[Any]:
    """The RenderOptions fields that are dpm-render flags, in declaration order."""
    return [f for f in fields(RenderOptions) if f.metadata.get("cli", True)]


def sidecar_types() -> dict[str, type]:
    """`[render]` keys a scene sidecar may set, with the TOML value type each must have."""
    kinds = {"int": int, "float": float, "str": str, "bool": bool}
    out = {}
    for f in cli_fields():
        if f.metadata["sidecar"]:
            out[f.name] = kinds[str(f.type).split(" |")[0]]
    return out


def default_text(f: Any) -> str:
    """How --help names a field's default."""
    if f.metadata.get("default_text"):
        return f.metadata["default_text"]
    return str(f.default) if f.default is not MISSING else "required"


def flag(name: str) -> str:
    """The command-line flag of a field name: photons_per_pass -> --photons-per-pass."""
    return "--" + name.replace("_", "-")
