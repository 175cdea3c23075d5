"""A damaged ``.vtu``/``.vtk`` is one ``InputError`` naming the file and the line of the first problem,
in words (found here: "SystemExit: 1", "ValueError: cannot reshape array of size 5746 into shape
(2160,3)", "KeyError: 'type'" and no line). Generated damage: cut at many points, a token replaced,
a count changed, the header or the XML broken."""

from __future__ import annotations

import re

import pytest
from conftest import run_ffd

from ffdcli.errors import InputError
from ffdcli.io.formats import read_mesh, write_mesh
from ffdcli.testing.wings import extruded_wing_mesh

INTERNALS = ("SystemExit", "ValueError", "KeyError", "IndexError", "Traceback", "reshape", "Couldn't read")


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    d = tmp_path_factory.mktemp("vtkgood")
    mesh = extruded_wing_mesh(n_around=21, n_radial=5, n_span=4)
    out = {}
    for ext in (".vtu", ".vtk"):
        write_mesh(mesh, d / f"g{ext}", mesh.points)
        out[ext] = (d / f"g{ext}").read_bytes()
    return out


def _damaged(good, ext: str, how: str) -> bytes:
    data = good[ext]
    if how.startswith("cut"):
        return data[:int(len(data) * float(how[3:]))]
    if ext == ".vtu":
        return {
            "tag": data.replace(b"</UnstructuredGrid>", b"</Unstructured>"),
            "count": data.replace(b'NumberOfPoints="', b'NumberOfPoints="x', 1),
            "cells": re.sub(rb"<Cells>.*?</Cells>", b"", data, flags=re.S),
            "junk": b"\x00\x01binary junk" * 40,
            "type": data.replace(b'type="UnstructuredGrid"', b'type="PolyData"', 1),
        }[how]
    i = data.index(b"POINTS")
    return {
        "tag": data.replace(b"DATASET UNSTRUCTURED_GRID", b"DATASET POLYDATA", 1),
        "count": data.replace(b"POINTS ", b"POINTS 9", 1),
        "cells": data[:data.index(b"CELL_TYPES")],
        "junk": b"hello world\n" * 10,
        "type": re.sub(rb"(CELL_TYPES \d+\n)(\d+)", rb"\g<1>99", data, count=1),
        "token": data[:i + 40] + b" abc " + data[i + 40:],
        "header": data[:data.index(b"ASCII")],
    }[how]


HOWS = {".vtu": ["cut0.01", "cut0.1", "cut0.3", "cut0.5", "cut0.7", "cut0.9", "cut0.99", "tag", "count",
                 "cells", "junk", "type"],
        ".vtk": ["cut0.05", "cut0.2", "cut0.4", "cut0.6", "cut0.75", "tag", "count", "cells", "junk", "type",
                 "token", "header"]}
CASES = [(ext, how) for ext, hows in HOWS.items() for how in hows]


@pytest.mark.parametrize("ext, how", CASES, ids=[f"{e[1:]}-{h}" for e, h in CASES])
def test_damaged_vtk_names_the_line(tmp_path, good, ext, how):
    path = tmp_path / f"bad{ext}"
    path.write_bytes(_damaged(good, ext, how))
    with pytest.raises(InputError) as e:
        read_mesh(path)
    text = e.value.format()
    assert e.value.line is not None and text.startswith(f"{path}:{e.value.line}: "), text
    assert not any(w in text for w in INTERNALS), text
    assert "expected a" in text and ext in text, text


def test_the_command_line_says_it_in_one_line(tmp_path, good):
    (tmp_path / "bad.vtk").write_bytes(_damaged(good, ".vtk", "cut0.4"))
    proc = run_ffd("inspect", "bad.vtk", cwd=tmp_path)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert re.match(r"ffd: error: bad\.vtk:\d+: POINTS declares \d+ numbers", proc.stderr), proc.stderr


def test_a_good_file_reads_as_before(tmp_path, good):
    for ext in (".vtu", ".vtk"):
        (tmp_path / f"g{ext}").write_bytes(good[ext])
        assert read_mesh(tmp_path / f"g{ext}").n_points > 0
