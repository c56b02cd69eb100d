"""Every kind of bad input: one line naming the file and the problem, exit 2, nothing written."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import trimesh

from conftest import FLOOR_AND_LIGHT_MTL, FLOOR_AND_LIGHT_OBJ, write_scene
from dpm.cli import render_main


def run_render(capsys, argv: list[str]) -> tuple[int, str]:
    """Run dpm-render in-process; return (exit status, stderr)."""
    try:
        code = render_main(argv)
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    return code, capsys.readouterr().err


def _closed_box_obj() -> str:
    """The floor-and-light scene plus a closed box with outward faces around (0, 0.4, 0)."""
    box = trimesh.creation.box(extents=(0.4, 0.4, 0.4))
    box.apply_translation((0, 0.4, 0))
    lines = [FLOOR_AND_LIGHT_OBJ, "usemtl floor"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in box.vertices]
    lines += [f"f {a + 9} {b + 9} {c + 9}" for a, b, c in box.faces]
    return "\n".join(lines) + "\n"


CAMERA_IN_BOX = "[camera]\norigin = [0, 0.4, 0]\ntarget = [0.3, 0, 0.1]\n"

CASES = {
    "missing file": (None, None, None, "file not found"),
    "bad vertex": (FLOOR_AND_LIGHT_OBJ.replace("v 1 0 -1", "v 1 zero -1"), None, None, ":3:"),
    "short vertex": (FLOOR_AND_LIGHT_OBJ.replace("v 1 0 -1", "v 1 0"), None, None, ":3:"),
    "face index out of range": (FLOOR_AND_LIGHT_OBJ + "f 1 2 99\n", None, None, "out of range"),
    "face index zero": (FLOOR_AND_LIGHT_OBJ + "f 0 1 2\n", None, None, "out of range"),
    "bad face token": (FLOOR_AND_LIGHT_OBJ + "f 1 a 2\n", None, None, "bad face vertex"),
    "two-vertex face": (FLOOR_AND_LIGHT_OBJ + "f 1 2\n", None, None, "at least 3"),
    "unknown OBJ statement": (FLOOR_AND_LIGHT_OBJ + "curv 0 1 2\n", None, None, "unsupported"),
    "unknown material": (FLOOR_AND_LIGHT_OBJ + "usemtl nope\nf 1 2 3\n", None, None, "'nope'"),
    "missing mtllib": (
        FLOOR_AND_LIGHT_OBJ.replace("scene.mtl", "gone.mtl"),
        None,
        None,
        "gone.mtl",
    ),
    "malformed MTL number": (None, FLOOR_AND_LIGHT_MTL + "Ni glass\n", None, "scene.mtl:5"),
    "malformed MTL count": (
        None,
        FLOOR_AND_LIGHT_MTL.replace("Kd 0.5 0.5 0.5", "Kd 1 2"),
        None,
        ":2:",
    ),
    "negative Kd": (None, FLOOR_AND_LIGHT_MTL.replace("Kd 0.5 0.5 0.5", "Kd -1 0 0"), None, ":2:"),
    "MTL field before newmtl": (
        None,
        "Kd 1 1 1\n" + FLOOR_AND_LIGHT_MTL,
        None,
        "before any newmtl",
    ),
    "unknown MTL statement": (None, FLOOR_AND_LIGHT_MTL + "glow 1\n", None, "unsupported MTL"),
    "bad illum": (None, FLOOR_AND_LIGHT_MTL + "illum 2.5\n", None, "illum"),
    "malformed TOML": (None, None, "[camera\norigin = [0,1,5]\n", "invalid TOML"),
    "unknown TOML section": (None, None, "[lights]\nx = 1\n", "unknown section"),
    "camera missing target": (None, None, "[camera]\norigin = [0, 1, 5]\n", "target"),
    "camera bad fov": (None, None, "[camera]\norigin=[0,1,5]\ntarget=[0,0,0]\nfov=190\n", "fov"),
    "camera bad vector": (None, None, "[camera]\norigin=[0,1]\ntarget=[0,0,0]\n", "origin"),
    "camera up parallel": (None, None, "[camera]\norigin=[0,5,0]\ntarget=[0,0,0]\n", "parallel"),
    "unknown render key": (None, None, "[render]\nsamples = 4\n", "unknown key"),
    "render key type": (None, None, "[render]\nspp = 'many'\n", "'spp'"),
    "no emitter": (FLOOR_AND_LIGHT_OBJ.replace("usemtl light\n", ""), None, None, "no emitter"),
    "lights face away": (FLOOR_AND_LIGHT_OBJ.replace("f 5 6 7 8", "f 5 8 7 6"), None, None, "away"),
    "camera inside an object": (_closed_box_obj(), None, CAMERA_IN_BOX, "inside a closed object"),
    "empty scene": ("mtllib scene.mtl\nv 0 0 0\n", None, None, "no faces"),
    "a NaN vertex": ("v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", None, None, "NaN or infinite"),
    "an infinite vertex": ("v 0 0 0\nv 1 0 0\nv 0 -inf 0\nf 1 2 3\n", None, None, "NaN or inf"),
    "only degenerate triangles": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", None, None, "no valid"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_scene_gives_one_line_and_exit_2(case: str, tmp_path: Path, capsys) -> None:
    obj, mtl, toml, expected = CASES[case]
    path = write_scene(
        tmp_path,
        obj if obj is not None else FLOOR_AND_LIGHT_OBJ,
        mtl if mtl is not None else FLOOR_AND_LIGHT_MTL,
        toml,
    )
    if case == "missing file":
        path = tmp_path / "absent.obj"
    out = tmp_path / "out.png"
    code, err = run_render(capsys, [str(path), "-o", str(out), "--quiet"])
    assert code == 2
    lines = [line for line in err.splitlines() if "warning" not in line]
    assert len(lines) == 1 and lines[0].startswith("dpm-render: error: ")
    assert expected in lines[0]
    assert "Traceback" not in err
    assert (
        sorted(p.name for p in tmp_path.iterdir() if p.suffix not in {".obj", ".mtl", ".toml"})
        == []
    )


@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        (["--spp", "0"], "--spp"),
        (["--k", "0"], "--k"),
        (["--photons", "-5"], "--photons"),
        (["--spp", "-3"], "--spp"),
        (["--seed", "-1"], "--seed"),
        (["--width", "0"], "--width"),
        (["--method", "sppm", "--component", "caustic", "--denoise"], "denoise"),
        (["--method", "pm", "--caustic-spp", "0"], "--caustic-spp"),
        (["--method", "pt", "--caustic-spp", "2"], "--caustic-spp"),
        (["--method", "pm", "--weights", "w.msgpack"], "--weights"),
        (["--method", "ppm", "--radius", "0"], "--radius"),
        (["--method", "appm", "--radius", "-0.1"], "--radius"),
        (["--method", "sppm", "--radius", "nan"], "--radius"),
        (["--method", "ppm", "--photons-per-pass", "0"], "--photons-per-pass"),
        (["--method", "pm", "--checkpoint", "c.npz"], "--checkpoint"),
        (["--method", "nonsense"], "invalid choice"),
        (["--method", "pt", "--component", "caustic"], "caustic"),
        (["--method", "pt-nocaustic", "--component", "caustic"], "caustic"),
        (["--spp", "many"], "invalid int"),
    ],
)
def test_bad_flags(flags: list[str], expected: str, scene_path: Path, capsys) -> None:
    out = scene_path.parent / "out.png"
    code, err = run_render(capsys, [str(scene_path), "-o", str(out), "--quiet", *flags])
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and expected in err
    assert not out.exists()


def test_bad_output_paths(scene_path: Path, capsys) -> None:
    folder = scene_path.parent
    for argv, expected in (
        (["-o", str(folder / "missing" / "out.png")], "output folder does not exist"),
        (["-o", str(folder / "out.jpg")], ".png or .exr"),
        (["--stats", str(folder / "missing" / "s.json")], "output folder does not exist"),
    ):
        code, err = run_render(capsys, [str(scene_path), "--quiet", *argv])
        assert code == 2 and expected in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in folder.iterdir()) == ["scene.mtl", "scene.obj"]


def test_dropped_triangles_warn_in_one_line(tmp_path: Path, capsys) -> None:
    obj = FLOOR_AND_LIGHT_OBJ + "v 2 0 0\nf 1 1 9\n"  # a triangle with no area
    path = write_scene(tmp_path, obj)
    code, err = run_render(
        capsys, [str(path), "-o", str(tmp_path / "o.png"), "--quiet", "--spp", "1"]
    )
    assert code == 0
    assert err.strip() == (
        f"dpm-render: warning: {path}: dropped 1 degenerate or out-of-range triangle(s)"
    )


def test_real_process_has_no_traceback(tmp_path: Path) -> None:
    """The installed entry point, as a user runs it, on a missing file."""
    code = "import sys; from dpm.cli import render_main; sys.exit(render_main())"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "nope.obj")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"dpm-render: error: {tmp_path / 'nope.obj'}: file not found"


EGG = Path(__file__).parent.parent / "examples" / "scenes" / "glass_egg.obj"


def test_k_above_the_caustic_photon_count_is_one_line(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out.png"
    argv = [str(EGG), "-o", str(out), "--quiet", "--width", "8", "--height", "8"]
    code, err = run_render(capsys, [*argv, "--method", "pm", "--photons", "2000", "--k", "1900"])
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "--k 1900 is more than the" in err and "caustic photons that 2000" in err
    assert not out.exists()


def test_k_above_the_emitted_paths_is_one_line_even_without_caustics(
    scene_path: Path, capsys
) -> None:
    out = scene_path.parent / "out.png"
    for method in ("pm", "dpm", "hybrid"):
        argv = [str(scene_path), "-o", str(out), "--quiet", "--method", method]
        code, err = run_render(capsys, [*argv, "--photons", "100", "--k", "500"])
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert "--k 500 is more than the 100 photon paths emitted" in err
        assert not out.exists()


def test_a_corrupt_or_foreign_checkpoint_is_one_line(tmp_path: Path, capsys) -> None:
    out, checkpoint = tmp_path / "out.png", tmp_path / "ppm.npz"
    argv = [str(EGG), "-o", str(out), "--quiet", "--width", "8", "--height", "8", "--spp", "1"]
    argv += ["--method", "ppm", "--photons", "20000", "--checkpoint", str(checkpoint)]
    checkpoint.write_bytes(b"PK\x03\x04 truncated")
    code, err = run_render(capsys, argv)
    assert code == 2 and "not a readable checkpoint" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    checkpoint.unlink()
    assert run_render(capsys, argv)[0] == 0 and checkpoint.exists()
    code, err = run_render(capsys, [*argv, "--seed", "5"])
    assert code == 2 and "checkpoint of another run" in err
