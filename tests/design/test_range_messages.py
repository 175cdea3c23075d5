"""A number out of its key's range is refused with the range in words, whatever form the key takes
(found here: ``hinge: 75`` said "expected another value, got 75": a key that takes a number or a list
named no range). Generated over every key of the design schema that has a numeric range, several
values out of range each."""

from __future__ import annotations

import pytest

from ffdcli.design import design_schema
from ffdcli.design.validate import validate_section
from ffdcli.errors import InputError

WORDS = {"exclusiveMinimum": "greater than", "minimum": "at least", "exclusiveMaximum": "less than",
         "maximum": "at most"}


def _ranged(node, at=()):
    """(key path, schema of the key, its numeric branch) of every key with a numeric range."""
    if not isinstance(node, dict):
        return
    branches = node.get("anyOf") or node.get("oneOf")
    if node.get("type") in ("number", "integer") and any(k in node for k in WORDS):
        yield at, node, node
    elif branches:
        for b in branches:
            if isinstance(b, dict) and b.get("type") in ("number", "integer") and any(k in b for k in WORDS):
                yield at, node, b
                break
    for key, sub in (node.get("properties") or {}).items():
        yield from _ranged(sub, at + (key,))
    if isinstance(node.get("items"), dict):
        yield from _ranged(node["items"], at + (0,))


def _outside(branch) -> list:
    """Values out of the branch's range: at an exclusive bound, just beyond, far beyond."""
    out = []
    for k, bound in ((k, branch[k]) for k in WORDS if k in branch):
        step = max(abs(bound), 1)
        if k == "exclusiveMinimum":
            out += [bound, bound - 0.1 * step, bound - 75 * step]
        elif k == "minimum":
            out += [bound - 1, bound - (10 if branch["type"] == "integer" else 0.001 * step)]
        elif k == "exclusiveMaximum":
            out += [bound, bound + 0.5 * step, 75 * step]
        else:
            out += [bound + 1, 100 * step]
    return [int(v) if branch["type"] == "integer" else float(v) for v in out]


CASES = [(at, node, branch, v) for at, node, branch in _ranged(design_schema()) for v in _outside(branch)]


def test_the_cases_cover_the_device_hinges_and_many_keys():
    keys = {".".join(map(str, at)) for at, *_ in CASES}
    assert any(k.endswith("flap.hinge") for k in keys) and any(k.endswith("slat.hinge") for k in keys)
    assert len(keys) >= 15 and len(CASES) >= 50


@pytest.mark.parametrize("at, node, branch, value", CASES,
                         ids=[f"{'.'.join(map(str, a))}={v:g}" for a, _, _, v in CASES])
def test_out_of_range_names_the_range(at, node, branch, value):
    with pytest.raises(InputError) as e:
        validate_section(value, node, at)
    text = str(e.value)
    assert f"got {value!r}" in text or f"got {value}" in text, text
    for k, word in WORDS.items():
        if k in branch:
            assert f"{word} {branch[k]:g}" in text or f"{word} {branch[k]}" in text, text
    assert "another value" not in text


@pytest.mark.parametrize("value, fraction", [(75, "0.75"), (30, "0.3"), (5, "0.05")])
def test_a_percentage_for_a_fraction_says_the_fraction(value, fraction):
    node = design_schema()["properties"]["changes"]["items"]["properties"]["flap"]["properties"]["hinge"]
    with pytest.raises(InputError, match=f"a fraction: {fraction} for {value} %"):
        validate_section(value, node, ("changes", 0, "flap", "hinge"))
