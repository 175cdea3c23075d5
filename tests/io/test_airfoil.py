"""ffdcli.io.formats.airfoil: Selig and Lednicer files in, Selig order out; clean errors for bad files."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import SAMPLES, shared_file

from ffdcli.errors import InputError
from ffdcli.io.formats.airfoil import Airfoil, read_airfoil, write_airfoil
from ffdcli.testing import wings


def _write(tmp_path, text, name="foil.dat"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _rows(coords):
    return "".join(f"{float(x)!r} {float(y)!r}\n" for x, y in coords)    # repr: exact round trip


def test_selig_read_exact(tmp_path):
    xy = wings.naca4("2412", 81)
    a = read_airfoil(_write(tmp_path, "NACA 2412\n" + _rows(xy)))
    assert isinstance(a, Airfoil) and a.name == "NACA 2412" and a.format == "selig"
    np.testing.assert_array_equal(a.coords, xy)


def test_lednicer_read_into_selig_order(tmp_path):
    xy = wings.naca4("2412", 81, closed_te=False)           # LE is point 40, shared by both sides
    upper, lower = xy[40::-1], xy[40:]                       # both from the LE to the TE
    text = (f"NACA 2412 Lednicer\n{len(upper)}.  {len(lower)}.\n\n" + _rows(upper) + "\n"
            + _rows(lower))
    a = read_airfoil(_write(tmp_path, text))
    assert a.format == "lednicer" and a.name == "NACA 2412 Lednicer"
    np.testing.assert_array_equal(a.coords, xy)              # shared LE point kept once


def test_no_name_line_and_clockwise_file(tmp_path):
    xy = wings.naca4("0012", 41)
    a = read_airfoil(_write(tmp_path, _rows(xy[::-1]), "my_foil.dat"))   # lower surface first
    assert a.name == "my_foil"
    np.testing.assert_array_equal(a.coords, xy)


def test_write_read_round_trip(tmp_path):
    xy = wings.naca4("4415", 99, closed_te=False)
    p = tmp_path / "out.dat"
    write_airfoil(p, "NACA 4415", xy)
    a = read_airfoil(p)
    assert a.name == "NACA 4415"
    np.testing.assert_allclose(a.coords, xy, rtol=0, atol=1e-14)   # %.15g of values < 2
    assert not list(tmp_path.glob(".*part*"))                      # atomic: no leftovers


@pytest.mark.parametrize("text, line, words", [
    ("", None, "empty"),
    ("\n  \n", None, "empty"),
    ("NACA 0012\n", 1, "no coordinates"),
    ("name\n1 0\n0.5 abc\n0 0\n0.5 -0.1\n1 0\n", 3, "two numbers"),
    ("name\n1 0\n0.5 nan\n0 0\n0.5 -0.1\n1 0\n", 3, "finite"),
    ("name\n1 0\n0.5 0.1\n0 inf\n0.5 -0.1\n1 0\n", 4, "finite"),
    ("name\n1 0\n0.5 0.1 7\n0 0\n0.5 -0.1\n1 0\n", 3, "two numbers"),
    ("name\n1 0\n0 0\n1 0\n", None, "at least 5"),
    ("name\n1 0\n0.5 0.1\n0 0\n0.5 -0.1\n0.2 -0.1\n1 0\n", 6, "not ordered like an airfoil"),
    ("name\n0 0\n0.5 0.1\n1 0\n0.5 -0.1\n0 0\n", None, "not ordered like an airfoil"),
    ("name\n3. 3.\n0 0\n0.5 0.1\n1 0\n0 0\n0.5 -0.1\n", 2, "Lednicer counts"),
])
def test_bad_files(tmp_path, text, line, words):
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as e:
        read_airfoil(p)
    assert e.value.line == line and words in e.value.message and str(p) in str(e.value)
    assert "\n" not in str(e.value)


def test_missing_and_binary(tmp_path):
    with pytest.raises(InputError, match="no such airfoil file"):
        read_airfoil(tmp_path / "nope.dat")
    p = tmp_path / "bin.dat"
    p.write_bytes(b"\xff\xfe\x00\x01" * 10)
    with pytest.raises(InputError, match="not a text file"):
        read_airfoil(p)


def test_bundled_samples():
    a = read_airfoil(SAMPLES / "naca0012.dat")
    np.testing.assert_allclose(a.coords, wings.naca4("0012", 133), atol=5e-8)   # written with %10.7f
    s = read_airfoil(SAMPLES / "s1223.dat")
    assert s.name == "S1223HiRes" and s.coords.shape == (300, 2)
    assert abs(s.coords[:, 0].min()) < 1e-4 and np.array_equal(s.coords[0], [1.0, 0.0])


@pytest.mark.parametrize("name, n", [("naca0012.dat", 69), ("naca2412.dat", 160), ("rae2822.dat", 129),
                                     ("s1223.dat", 300), ("sc20714.dat", 205)])
def test_shared_data_airfoils(name, n):
    a = read_airfoil(shared_file(f"airfoils/{name}"))
    assert a.coords.shape == (n, 2) and a.format == "selig"
    assert a.coords[0, 0] == pytest.approx(1.0) and a.coords[-1, 0] == pytest.approx(1.0)
    # the leading edge is at x = 0 to the files' precision (S1223: -2e-5, NACA 2412: 6e-6)
    assert abs(a.coords[:, 0].min()) < 1e-4 and wings.polygon_area(a.coords) > 0
