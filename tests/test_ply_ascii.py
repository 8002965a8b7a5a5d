"""ASCII PLY bodies parsed by numpy (asrbf_mesh._ply_ascii): the same arrays, or the same
error, as plyfile's row-by-row reading, on plain files and on every malformed variant."""

from __future__ import annotations

import io
import warnings

import numpy as np
import plyfile
import pytest

from asrbf_mesh import _readers
from asrbf_mesh._io import load_scan
from asrbf_mesh._ply_ascii import read_ascii_body
from asrbf_mesh.errors import ScanError

HEADER = (
    "ply\nformat ascii 1.0\ncomment made by a test\nelement vertex {nv}\n"
    "property float x\nproperty float y\nproperty double z\nproperty uchar red\n"
    "element face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
)


def _mesh(rng: np.random.Generator, quads: bool = False) -> tuple[str, str]:
    """A 6 x 5 grid's vertices (with a colour) and faces as ASCII rows."""
    u, v = np.meshgrid(np.arange(6.0), np.arange(5.0))
    z = rng.normal(size=u.shape).round(4)
    rows = [f"{a:g} {b:g} {float(c)!r} {int(k)}" for a, b, c, k in
            zip(u.ravel(), v.ravel(), z.ravel(), rng.integers(0, 256, u.size), strict=True)]
    faces = []
    for i in range(4):
        for j in range(5):
            a, b, c, d = i * 6 + j, i * 6 + j + 1, (i + 1) * 6 + j + 1, (i + 1) * 6 + j
            if quads and (i + j) % 2:
                faces.append(f"4 {a} {b} {c} {d}")
            else:
                faces += [f"3 {a} {b} {c}", f"3 {a} {c} {d}"]
    return "\n".join(rows), "\n".join(faces)


def _ply(vertices: str, faces: str, nv: int = 30, nf: int | None = None) -> bytes:
    nf = faces.count("\n") + 1 if nf is None else nf
    return (HEADER.format(nv=nv, nf=nf) + vertices + "\n" + faces + "\n").encode()


def _outcome(path, monkeypatch, fast: bool):
    """``load_scan``'s points and faces, or its error message, with or without the shortcut."""
    with monkeypatch.context() as m:
        if not fast:
            m.setattr(_readers, "read_ascii_body", lambda head, body: False)
        try:
            scan = load_scan(path, min_points=3, height_field=False)
        except ScanError as exc:
            return str(exc)
    return scan.points, scan.faces


def _variants(rng: np.random.Generator) -> dict[str, bytes]:
    verts, faces = _mesh(rng)
    qverts, qfaces = _mesh(rng, quads=True)
    vlines = verts.split("\n")
    flines = faces.split("\n")
    return {
        "plain": _ply(verts, faces),
        "quads": _ply(qverts, qfaces),
        "crlf": _ply(verts, faces).replace(b"\n", b"\r\n"),
        "cr only": _ply(verts, faces).replace(b"\n", b"\r"),
        "tabs and padding": _ply(verts.replace(" ", "\t  "), faces.replace("\n", "  \n ")),
        "trailing text": _ply(verts, faces) + b"\n\nsome trailing words\n",
        "no final newline": _ply(verts, faces)[:-1],
        "blank line": _ply(verts, faces.replace("\n", "\n\n", 1)),
        "row split": _ply("\n".join(vlines[:3] + [vlines[3].replace(" ", "\n", 1)]
                                    + vlines[4:]), faces),
        "extra value": _ply(verts.replace("\n", " 7\n", 1), faces),
        "missing value": _ply("\n".join([vlines[0].rsplit(" ", 1)[0]] + vlines[1:]), faces),
        "shifted values": _ply("\n".join([vlines[0] + " 1", vlines[1].rsplit(" ", 1)[0]]
                                         + vlines[2:]), faces),
        "word": _ply(verts.replace(" ", " x", 1), faces),
        "colour out of range": _ply(verts.rsplit(" ", 1)[0] + " 256", faces),
        "fractional colour": _ply(verts.rsplit(" ", 1)[0] + " 2.5", faces),
        "fractional index": _ply(verts, faces.replace("3 0 1", "3 0.5 1", 1)),
        "negative index": _ply(verts, faces.replace("3 0 1", "3 -1 1", 1)),
        "index past the end": _ply(verts, faces.replace("3 0 1", "3 30 1", 1)),
        "list length lies": _ply(verts, faces.replace("3 0 1", "4 0 1", 1)),
        "nan coordinate": _ply("\n".join(["0 0 nan 12"] + vlines[1:]), faces),
        "fewer rows than announced": _ply(verts, "\n".join(flines[:-3]), nf=len(flines)),
        "counts too small": _ply(verts, faces, nv=29, nf=len(flines) - 1),
        "non-ascii byte": _ply(verts, faces).replace(b"3 0 1", b"3 \xe9 1", 1),
        "no faces": _ply(verts, "", nf=0).replace(b"\n\n", b"\n"),
    }


@pytest.mark.parametrize("seed", [0, 1])
def test_shortcut_reads_as_plyfile_does(tmp_path, monkeypatch, seed) -> None:
    rng = np.random.default_rng(seed)
    for name, content in _variants(rng).items():
        path = tmp_path / f"{name.replace(' ', '_')}.ply"
        path.write_bytes(content)
        fast = _outcome(path, monkeypatch, fast=True)
        slow = _outcome(path, monkeypatch, fast=False)
        if isinstance(slow, str):
            assert fast == slow, name
        else:
            assert not isinstance(fast, str), (name, fast)
            assert np.array_equal(fast[0], slow[0], equal_nan=True), name
            assert fast[0].dtype == slow[0].dtype, name
            assert (fast[1] is None) == (slow[1] is None), name
            if slow[1] is not None:
                assert np.array_equal(fast[1], slow[1]), name
        assert path.read_bytes() == content  # the input is never modified


def _taken(content: bytes) -> bool:
    stream = io.BytesIO(content)
    head = plyfile.PlyData._parse_header(stream)
    return read_ascii_body(head, stream.read())


def test_shortcut_taken_on_plain_files_only() -> None:
    variants = _variants(np.random.default_rng(3))
    taken = {name for name, content in variants.items() if _taken(content)}
    # the plain layouts (quads too) go through numpy; every malformed one is left to plyfile
    assert {"plain", "quads", "crlf", "tabs and padding", "trailing text", "no final newline",
            "no faces", "nan coordinate", "negative index", "index past the end"} <= taken
    assert not taken & {"cr only", "blank line", "row split", "extra value", "missing value",
                        "shifted values", "word", "colour out of range", "fractional colour",
                        "fractional index",
                        "list length lies", "fewer rows than announced", "counts too small",
                        "non-ascii byte"}


def test_mutated_files_read_as_plyfile_reads_them(tmp_path, monkeypatch) -> None:
    """A short differential fuzz: bytes of the variants' bodies deleted, inserted or
    replaced (numbers, signs, dots, exponents, whitespace, line ends)."""
    rng = np.random.default_rng(7)
    bases = list(_variants(np.random.default_rng(5)).values())
    pieces = [b" ", b"\n", b"\r", b"\t", b"0", b"-", b".", b"e", b"nan", b"3", b"4", b"255",
              b"256", b"1e9", b"x", b"\r\n", b""]
    path = tmp_path / "m.ply"
    taken = 0
    for _ in range(400):
        b = bytearray(bases[rng.integers(len(bases))])
        start = b.index(b"end_header") + 11
        for _ in range(rng.integers(1, 4)):
            pos = int(rng.integers(start, len(b)))
            op = rng.integers(3)
            if op == 0:
                del b[pos:pos + int(rng.integers(1, 4))]
            else:
                b[pos:pos + (op == 2)] = pieces[rng.integers(len(pieces))]
        path.write_bytes(bytes(b))
        taken += _taken(bytes(b))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # plyfile's own overflow and empty-list notes
            fast = _outcome(path, monkeypatch, fast=True)
            slow = _outcome(path, monkeypatch, fast=False)
        if isinstance(slow, str) or isinstance(fast, str):
            assert fast == slow
        else:
            assert np.array_equal(fast[0], slow[0], equal_nan=True)
            assert (fast[1] is None and slow[1] is None) or np.array_equal(fast[1], slow[1])
    assert taken >= 20  # some mutants stay plain (a digit for a digit, a space more)

