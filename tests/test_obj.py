"""The OBJ reader's two paths: the numpy one for the files exporters write and the statement
by statement one, which must agree wherever the first answers, and the second names errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dpm.errors import InputError
from dpm.obj import _read_any, _read_lines, _read_plain, read_obj

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenes"

SQUARE = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
UV = "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"

# Files the numpy path parses: every feature it handles, one per case.
PLAIN = {
    "triangles": SQUARE + "f 1 2 3\nf 1 3 4\n",
    "quad and pentagon fans": SQUARE + "v 0.5 2 0\nf 1 2 3 4\nf 1 2 3 5 4\n",
    "comments and blank lines": "# header\n\n" + SQUARE + "   \n#x\nf 1 2 3\n",
    "ignored statements": "o a\ng b\ns 1\n" + SQUARE + "vn 0 0 1\nf 1 2 3\n",
    "v/t": SQUARE + UV + "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
    "v/t/n": SQUARE + UV + "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n",
    "v//n": SQUARE + "vn 0 0 1\nf 1//1 2//1 3//1\n",
    "vt u v w": SQUARE + "vt 0 0 0\nvt 1 0 0\nvt 1 1 0\nf 1/1 2/2 3/3\n",
    "a vt out of range: untextured": SQUARE + UV[:14] + "f 1/1 2/2 3/3\nf 1/1 3/9 4/2\n",
    "a vt defined after the face": SQUARE + "f 1/1 2/2 3/3\n" + UV,
    "materials, one used twice": "mtllib a b.mtl\n" + SQUARE + "f 1 2 3\nusemtl red # c\nf 1 3 4\n"
    "usemtl blue\nf 1 2 4\nusemtl red\nf 2 3 4\n",
}

# Files it passes to the statement reader (which parses them or names the line).
OTHER = {
    "negative indices": SQUARE + "f -4 -3 -2\n",
    "vertex w": "v 0 0 0 1\nv 1 0 0 1\nv 1 1 0 1\nf 1 2 3\n",
    "tabs": "v\t0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "a leading space": " v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "double spaces": "v 0  0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "a comment after a vertex": "v 0 0 0 # a\nv 1 0 0\nv 1 1 0\nf 1 2 3\n",
    "mixed face forms": SQUARE + UV + "f 1/1/1 2 3\n",
    "mixed forms in a file": SQUARE + UV + "f 1/1 2/2 3/3\nf 1 3 4\n",
    "a tab inside a vt, a space after the last": SQUARE + "vt 0.1\t0.2 0.3 0.4\nvt 0.5 0.6 \n"
    "f 1/1 2/2 3/1\n",
    "two spaces before the first vt": SQUARE + "vt  0.5 0.6\nvt 0.1 0.2 0.3\t0.4\nf 1/1 2/2 3/1\n",
}

# Errors, with the line the statement reader names.
ERRORS = {
    "a face before its vertex": (SQUARE + "f 1 2 5\nv 0 0 1\n", ":5:"),
    "index zero": (SQUARE + "f 0 1 2\n", ":5:"),
    "a two-vertex face": (SQUARE + "f 1 2\n", ":5:"),
    "a NaN vertex": ("v 0 0 0\nv nan 0 0\nv 1 1 0\nf 1 2 3\n", ":2:"),
    "a word": ("v 0 0 0\nv 1 x 0\nv 1 1 0\nf 1 2 3\n", ":2:"),
    "an unknown statement": (SQUARE + "curv 0 1\nf 1 2 3\n", ":5:"),
    "usemtl without a name": (SQUARE + "usemtl\nf 1 2 3\n", ":5:"),
    "a short vertex after a tab": ("v 1\t2 3 4\nv 7 8 9\nv 5 6 \nf 1 2 3\n", ":3:"),
}


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "m.obj"
    path.write_text(text)
    return path


def _assert_same(a, b) -> None:
    for name in ("vertices", "faces", "face_material", "texcoords", "face_texcoords"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), name
    assert a.material_names == b.material_names and a.mtllibs == b.mtllibs


@pytest.mark.parametrize("case", sorted(PLAIN))
def test_the_numpy_path_agrees_with_the_statement_reader(tmp_path: Path, case: str) -> None:
    path = _write(tmp_path, PLAIN[case])
    lines = _read_lines(path)
    plain = _read_plain(path, lines)
    assert plain is not None, "the numpy path should parse this file"
    _assert_same(plain, _read_any(path, lines))


@pytest.mark.parametrize("case", sorted(OTHER))
def test_other_files_go_to_the_statement_reader(tmp_path: Path, case: str) -> None:
    path = _write(tmp_path, OTHER[case])
    assert _read_plain(path, _read_lines(path)) is None
    mesh = read_obj(path)
    assert len(mesh.faces) >= 1 and np.isfinite(mesh.vertices).all()
    _assert_same(mesh, _read_any(path, _read_lines(path)))


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_errors_name_their_line(tmp_path: Path, case: str) -> None:
    text, line = ERRORS[case]
    with pytest.raises(InputError, match=line):
        read_obj(_write(tmp_path, text))


def test_the_two_paths_agree_on_the_examples() -> None:
    for path in sorted(EXAMPLES.glob("*.obj")):
        lines = _read_lines(path)
        plain = _read_plain(path, lines)
        assert plain is not None, path.name
        _assert_same(plain, _read_any(path, lines))
