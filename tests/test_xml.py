"""Scenes users already have: Mitsuba 3 XML (the subset of `dpm.mitsuba_xml`) and PLY meshes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dpm
from dpm.cli import render_main

# A floor (rectangle scaled by 2), a mirror cube, a glass box from an OBJ and a light facing
# down (a rectangle turned by an exact matrix), seen by a camera looking down -z.
XML = """<scene version="3.0.0">
    <default name="w" value="24"/>
    <bsdf type="twosided" id="grey"><bsdf type="diffuse">
        <rgb name="reflectance" value="0.5, 0.4, 0.3"/></bsdf></bsdf>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" angle="-90"/><scale value="2"/></transform>
        <ref id="grey"/>
    </shape>
    <shape type="cube">
        <transform name="to_world"><scale value="0.25"/><translate x="0.5" y="0.25"/></transform>
        <bsdf type="conductor"><rgb name="specular_reflectance" value="0.9"/></bsdf>
    </shape>
    <shape type="MESH">
        <string name="filename" value="box.MESH"/>
        <bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>
    </shape>
    <shape type="rectangle">
        <transform name="to_world">
            <matrix value="0.25 0 0 0  0 0 -1 2  0 0.25 0 0  0 0 0 1"/>
        </transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="8, 8, 8"/></emitter>
    </shape>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 4" target="0, 1, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm"><integer name="width" value="$w"/>
            <integer name="height" value="20"/></film>
    </sensor>
</scene>
"""
BOX = [(-0.6, 0, -0.2), (-0.2, 0, -0.2), (-0.2, 0.4, -0.2), (-0.6, 0.4, -0.2), (-0.6, 0, 0.2),
       (-0.2, 0, 0.2), (-0.2, 0.4, 0.2), (-0.6, 0.4, 0.2)]  # fmt: skip
BOX_FACES = [
    (0, 2, 1),
    (0, 3, 2),
    (4, 5, 6),
    (4, 6, 7),
    (0, 1, 5),
    (0, 5, 4),
    (3, 7, 6),
    (3, 6, 2),
    (0, 4, 7),
    (0, 7, 3),
    (1, 2, 6),
    (1, 6, 5),
]  # fmt: skip  (outwards)


def rectangle(scale: float, matrix: np.ndarray, offset=(0.0, 0.0, 0.0)) -> list[np.ndarray]:
    """The world vertices of Mitsuba's rectangle under a linear map and an offset."""
    corners = np.array([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], float) * scale
    return list(corners @ matrix.T + offset)


def equivalent_obj(folder: Path) -> Path:
    """The XML scene written as OBJ + MTL + TOML, triangle for triangle in the same order."""
    turn = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float)  # rotate x by -90 degrees
    floor = rectangle(2.0, turn)
    cube = [np.array((x, y, z)) * 0.25 + (0.5, 0.25, 0) for x in (-1, 1) for y in (-1, 1)
            for z in (-1, 1)]  # fmt: skip
    light = rectangle(1.0, np.array([[0.25, 0, 0], [0, 0, -1], [0, 0.25, 0]]), (0, 2, 0))
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    lines = ["mtllib scene.mtl"]
    faces = []

    def add(vertices, tris, material):
        base = sum(1 for line in lines if line.startswith("v "))
        lines.extend("v " + " ".join(repr(float(c)) for c in v) for v in vertices)
        faces.append(f"usemtl {material}")
        faces.extend(f"f {a + base + 1} {b + base + 1} {c + base + 1}" for a, b, c in tris)

    add(floor, [(0, 1, 2), (0, 2, 3)], "grey")
    add(cube, [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))], "chrome")
    add(BOX, BOX_FACES, "glass")
    add(light, [(0, 1, 2), (0, 2, 3)], "light")
    (folder / "scene.obj").write_text("\n".join(lines + faces) + "\n")
    (folder / "scene.mtl").write_text(
        "newmtl grey\nKd 0.5 0.4 0.3\nnewmtl chrome\nillum 3\nKs 0.9 0.9 0.9\n"
        "newmtl glass\nillum 7\nNi 1.5\nnewmtl light\nKd 0 0 0\nKe 8 8 8\n"
    )
    (folder / "scene.toml").write_text(
        "[camera]\norigin = [0, 1, 4]\ntarget = [0, 1, 0]\nup = [0, 1, 0]\nfov = 40\n"
        "width = 24\nheight = 20\n"
    )
    return folder / "scene.obj"


def write_box(folder: Path, kind: str) -> None:
    """The glass box as box.obj or box.ply (ASCII)."""
    if kind == "obj":
        text = "".join(f"v {x} {y} {z}\n" for x, y, z in BOX)
        text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in BOX_FACES)
    else:
        text = (f"ply\nformat ascii 1.0\nelement vertex {len(BOX)}\nproperty float x\n"
                f"property float y\nproperty float z\nelement face {len(BOX_FACES)}\n"
                "property list uchar int vertex_indices\nend_header\n")  # fmt: skip
        text += "".join(f"{x} {y} {z}\n" for x, y, z in BOX)
        text += "".join(f"3 {a} {b} {c}\n" for a, b, c in BOX_FACES)
    (folder / f"box.{kind}").write_text(text)


@pytest.mark.parametrize("mesh", ["obj", "ply"])
def test_an_xml_scene_renders_as_its_obj_twin(tmp_path: Path, mesh: str) -> None:
    """The same scene from Mitsuba XML (rectangle, cube, obj or ply shapes, transforms,
    twosided/diffuse/conductor/dielectric, an area light, $defaults) and from OBJ + TOML: the
    same triangles, materials and camera, so the same image."""
    write_box(tmp_path, mesh)
    xml = tmp_path / "scene.xml"
    xml.write_text(XML.replace("MESH", mesh))
    from_xml = dpm.load_file(xml)
    from_obj = dpm.load_file(equivalent_obj(tmp_path))
    np.testing.assert_allclose(from_xml.triangles, from_obj.triangles, atol=1e-6)
    for field in ("kind", "albedo", "specular", "emission", "ior"):
        np.testing.assert_array_equal(
            getattr(from_xml.materials, field)[from_xml.material],
            getattr(from_obj.materials, field)[from_obj.material],
        )
    assert (from_xml.camera.width, from_xml.camera.height) == (24, 20)
    options = dict(method="pt", spp=2, seed=1, progress=False)
    image, twin = dpm.render(from_xml, **options), dpm.render(from_obj, **options)
    # The two loaders' float32 vertices agree to about 1e-7, not bit for bit: a shadow ray
    # grazing an edge may go either way, so a pixel of the 480 may differ by a path's light.
    differ = ~np.isclose(image, twin, rtol=1e-4, atol=1e-5).all(axis=-1)
    assert differ.sum() <= 2, np.argwhere(differ)
    assert image.mean() > 0 and abs(image.mean() - twin.mean()) < 0.01 * image.mean()


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (
            ('<shape type="cube">', '<shape type="cylinder">'),
            '<shape type="cylinder">: unsupported',
        ),
        (("<sensor", '<emitter type="envmap"/><sensor'), '<emitter type="envmap">: not supported'),
        (('value="$w"', 'value="$width"'), "$width has no <default>"),
        (('<bsdf type="conductor">', '<bsdf type="roughplastic">'), "unsupported bsdf"),
        (("</scene>", ""), "invalid XML"),
        (("box.MESH", "missing.obj"), "missing.obj: file not found"),
    ],
)
def test_what_is_not_read_is_one_line_and_exit_2(tmp_path, capsys, change, expected) -> None:
    write_box(tmp_path, "obj")
    xml = tmp_path / "scene.xml"
    xml.write_text(XML.replace(*change).replace("MESH", "obj"))
    code = render_main([str(xml), "-o", str(tmp_path / "o.png"), "--quiet", "--spp", "1"])
    err = capsys.readouterr().err
    assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o.png").exists()


def test_settings_dpm_chooses_itself_are_one_warning_line_each(tmp_path: Path) -> None:
    write_box(tmp_path, "obj")
    xml = tmp_path / "scene.xml"
    xml.write_text(XML.replace("MESH", "obj").replace(
        "<sensor", '<integrator type="path"/><sensor').replace(
        "<film", '<sampler type="independent"><integer name="sample_count" value="64"/>'
        "</sampler><film"))  # fmt: skip
    with pytest.warns(UserWarning) as caught:
        dpm.load_file(xml)
    messages = sorted(str(w.message) for w in caught)
    assert len(messages) == 2 and "<integrator> ignored" in messages[0]
    assert "<sampler> ignored" in messages[1]


def test_a_sphere_is_closed_and_faces_out() -> None:
    from dpm.mitsuba_xml import sphere

    vertices, faces = sphere(np.array([1.0, 2.0, 3.0]), 0.5)
    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = np.einsum("ij,ij->i", normal, tri.mean(axis=1) - (1, 2, 3))
    assert (outward > 0).all()
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), 1)
    _, count = np.unique(edges, axis=0, return_counts=True)
    assert (count == 2).all()  # closed: every edge shared by two triangles
    volume = np.einsum("ij,ij->i", tri[:, 0] - (1, 2, 3), np.cross(tri[:, 1] - (1, 2, 3),
                       tri[:, 2] - (1, 2, 3))).sum() / 6  # fmt: skip
    assert volume == pytest.approx(4 / 3 * np.pi * 0.5**3, rel=2e-3)


@pytest.mark.validation
def test_mitsuba_renders_the_same_xml_to_the_same_image_mean(tmp_path: Path) -> None:
    """Mitsuba 3 reads the XML itself (its path integrator, a box filter): dpm's path tracer
    on dpm's reading of it agrees within the noise of the two image means."""
    from dpm.validation.mitsuba import load_mitsuba

    mi = load_mitsuba()
    write_box(tmp_path, "ply")
    xml = tmp_path / "scene.xml"
    xml.write_text(XML.replace("MESH", "ply").replace(
        "<film type=\"hdrfilm\">", "<film type=\"hdrfilm\"><rfilter type=\"box\"/>"))  # fmt: skip
    with pytest.warns(UserWarning, match="rfilter"):
        scene = dpm.load_file(xml)
    spp = 2048
    ours = [dpm.render(scene, method="pt", spp=spp, seed=s, progress=False) for s in (1, 2)]
    mitsuba_scene, path = mi.load_file(str(xml)), mi.load_dict({"type": "path"})
    theirs = [np.array(mi.render(mitsuba_scene, spp=spp, seed=s, integrator=path)) for s in (1, 2)]
    means = [np.mean(x) for x in (*ours, *theirs)]
    spread = abs(means[0] - means[1]) + abs(means[2] - means[3])  # each side's own noise
    difference = abs((means[0] + means[1]) - (means[2] + means[3])) / 2
    assert difference < max(3 * spread, 0.01 * np.mean(means)), means


# A light of radiance 1 filling the view, seen through a thin sheet of glass at normal
# incidence (Mitsuba's thindielectric): T' = 1 - 2F/(1+F) of it comes through.
THIN_SHEET = """<scene version="3.0.0">
    <shape type="rectangle">
        <transform name="to_world"><scale value="4"/><translate z="-2"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="1"/></emitter>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="4"/></transform>
        <bsdf type="thindielectric"><float name="int_ior" value="1.5"/>
            <rgb name="specular_transmittance" value="1, 0.5, 0.25"/></bsdf>
    </shape>
    <sensor type="perspective">
        <float name="fov" value="2"/>
        <transform name="to_world"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm"><integer name="width" value="16"/>
            <integer name="height" value="16"/></film>
    </sensor>
</scene>
"""


def test_a_thin_sheet_passes_one_minus_its_summed_reflection(tmp_path: Path) -> None:
    (tmp_path / "thin.xml").write_text(THIN_SHEET)
    scene = dpm.load_file(tmp_path / "thin.xml")
    assert dpm.scene.KIND_NAMES[scene.materials.kind[1]] == "thin dielectric"
    f = ((1.5 - 1) / (1.5 + 1)) ** 2  # Fresnel at normal incidence
    through = 1 - 2 * f / (1 + f)
    image = dpm.render(scene, "pt", spp=256, progress=False)
    mean = image.reshape(-1, 3).mean(axis=0)
    # each sample passes (weight Tf) or reflects into the dark: a Bernoulli mean over 65,536
    err = 4 * np.sqrt(through * (1 - through) / image[..., 0].size / 256)
    assert np.allclose(mean, through * np.array([1, 0.5, 0.25]), atol=err), mean


@pytest.mark.validation
def test_mitsuba_agrees_on_the_thin_sheet(tmp_path: Path) -> None:
    """Mitsuba 3's thindielectric passes the same share of the light as dpm's thin sheet."""
    from dpm.validation.mitsuba import load_mitsuba

    mi = load_mitsuba()
    (tmp_path / "thin.xml").write_text(THIN_SHEET)
    ours = dpm.render(dpm.load_file(tmp_path / "thin.xml"), "pt", spp=256, progress=False)
    scene, path = mi.load_file(str(tmp_path / "thin.xml")), mi.load_dict({"type": "path"})
    theirs = np.array(mi.render(scene, spp=256, seed=1, integrator=path))
    a, b = ours.reshape(-1, 3).mean(axis=0), theirs.reshape(-1, 3).mean(axis=0)
    assert np.allclose(a, b, rtol=0.02), (a, b)
