"""ffdcli.settings: the lattice settings value, its one rule of degree against points, its cache key."""

from __future__ import annotations

import pytest

from ffdcli.errors import InputError
from ffdcli.settings import DEFAULT_POINTS, MAX_DEGREE, BoxSettings, check_degree, default_degree


def test_defaults_are_filled_in_by_checked():
    for dim, pts in DEFAULT_POINTS.items():
        s = BoxSettings().checked(dim)
        assert s.points == pts and s.degree == tuple(default_degree(p) for p in pts)
        assert s.checked(dim) == s                          # checking twice changes nothing
    assert default_degree(2) == 1 and default_degree(4) == 3 and default_degree(9) == 3


@pytest.mark.parametrize("points, degree, key, words", [
    ((6, 8, 2), (3, 3, 2), "box.degree[2]", "at least 3 points"),
    ((6, 8, 2), (MAX_DEGREE + 1, 3, 1), "box.degree[0]", f"use 1 to {MAX_DEGREE}"),
    ((6, 8, 2), (0, 3, 1), "box.degree[0]", "not supported"),
])
def test_one_rule_of_degree_against_points(points, degree, key, words):
    with pytest.raises(InputError, match=words) as e:
        check_degree(points, degree)
    assert e.value.key == key
    with pytest.raises(InputError, match=words):
        BoxSettings(points=points, degree=degree).checked(3)


def test_cache_key_follows_the_settings_and_as_dict_round_trips():
    a = BoxSettings(points=(6, 8, 2), margin=0.05).checked(3)
    assert a.get_cache_key() == BoxSettings.from_dict(a.as_dict()).get_cache_key()
    assert BoxSettings.from_dict(a.as_dict()) == a
    assert a.get_cache_key() != BoxSettings(points=(6, 9, 2), margin=0.05).checked(3).get_cache_key()
    assert a.get_cache_key() != BoxSettings(points=(6, 8, 2), margin=0.06).checked(3).get_cache_key()


def test_options_over_a_design_box():
    design = BoxSettings(points=(6, 8, 2), degree=(3, 3, 1), margin=0.05)
    assert design.with_options(points=None, margin=None) == design
    moved = design.with_options(points=(8, 10, 2))
    assert moved.points == (8, 10, 2) and moved.degree is None and moved.margin == 0.05
    both = design.with_options(points=(8, 10, 3), degree=(2, 2, 2), sections="xz")
    assert both.degree == (2, 2, 2) and both.sections == "xz"
