"""Axis detection: the root plane (free edges at one end of the span) tells span from chord."""

from __future__ import annotations

import pytest

from ffdcli.box.box import fit_box
from ffdcli.geometry.axes import detect_axes, free_edge_nodes
from ffdcli.geometry.surface import extract_surface
from ffdcli.settings import BoxSettings
from ffdcli.testing.wings import Planform, surface_mesh

SECTIONS = ["xy", "xz", "yz", "yx", "zx", "zy"]


def _fin(sections, sign, **kw):
    """A swept, tapered, low-aspect-ratio surface (a fin or tail: chord and span extents alike)."""
    pf = Planform(semi_span=kw.pop("semi_span", 1.0), root_chord=1.0, taper=0.6, le_sweep_deg=35,
                  sections=sections, span_sign=sign, root_offset=(0.3, -0.2, 0.5), **kw)
    m = surface_mesh(pf, 21, 9, **{k: v for k, v in kw.items() if k in ("tip", "root")})
    return extract_surface(m, ["wing"])


@pytest.mark.parametrize("sections", SECTIONS)
@pytest.mark.parametrize("sign", [1, -1])
def test_root_plane_gives_span_and_root_of_low_aspect_ratio_fins(sections, sign):
    s = _fin(sections, sign)
    a = detect_axes(s.points, 3, faces=s.faces)
    want = {"chord": sections[0], "thickness": sections[1], "span": ({"x", "y", "z"} - set(sections)).pop()}
    assert a.as_dict() == want
    assert a.root == ("min" if sign > 0 else "max")
    assert not a.guessed


def test_extents_alone_get_such_a_fin_wrong():
    """Why the root plane is needed: the chordwise extent of a swept fin exceeds its span."""
    s = _fin("xy", 1)
    assert detect_axes(s.points, 3).as_dict()["span"] != "z"


def test_closed_surface_falls_back_to_extents():
    pf = Planform(semi_span=3.0, sections="xz")
    s = extract_surface(surface_mesh(pf, 21, 9, root="closed"), ["wing", "root"])
    assert len(free_edge_nodes(s.faces, len(s.points))) == 0
    assert detect_axes(s.points, 3, faces=s.faces).as_dict() == {"chord": "x", "thickness": "z", "span": "y"}


def test_user_root_wins_over_the_plane():
    s = _fin("xy", 1)
    assert detect_axes(s.points, 3, faces=s.faces, root="max").root == "max"


@pytest.mark.parametrize("sections,sign", [("xy", 1), ("zx", -1)])
def test_box_fits_a_fin_with_the_detected_axes(sections, sign):
    s = _fin(sections, sign)
    box, emb, report = fit_box(s.points, s.faces, BoxSettings(points=(5, 4, 2)), dim=3)
    assert emb.inside.all()
    assert box.summary()["axes"]["span"] == ({"x", "y", "z"} - set(sections)).pop()
    assert not any("not clearly wing-shaped" in w for w in report.get("warnings", []))
