"""``box.degree`` above ``settings.MAX_DEGREE`` (5, the compiled lattice kernels' work arrays) is refused
where the file is checked, with the limit in words, by the schema and the one rule alike. Found here:
the schema and the docs allowed any degree and the run refused it later (SU2's own degree-14 RAE2822
box cannot be mirrored; docs/design-file.md says so)."""

from __future__ import annotations

import pytest

from ffdcli.design import design_schema
from ffdcli.design.validate import validate_section
from ffdcli.errors import InputError
from ffdcli.settings import MAX_DEGREE, check_degree


@pytest.mark.parametrize("degree", [MAX_DEGREE + 1, 7, 9, 14, 40])
@pytest.mark.parametrize("direction", [0, 1])
def test_a_degree_above_the_limit_is_refused_by_the_schema(degree, direction):
    node = design_schema()["properties"]["box"]["properties"]["degree"]
    value = [3, 3]
    value[direction] = degree
    with pytest.raises(InputError, match=f"at least 1 and at most {MAX_DEGREE}, got {degree}") as e:
        validate_section(value, node, ("box", "degree"))
    assert e.value.key == f"box.degree[{direction}]"
    with pytest.raises(InputError, match=f"use 1 to {MAX_DEGREE}"):
        check_degree([degree + 1, degree + 1], value)


@pytest.mark.parametrize("degree", range(1, MAX_DEGREE + 1))
def test_every_degree_up_to_the_limit_passes_both(degree):
    node = design_schema()["properties"]["box"]["properties"]["degree"]
    validate_section([degree, 1], node, ("box", "degree"))
    check_degree([degree + 1, 2], [degree, 1])
    assert f"1 to {MAX_DEGREE}" in node["description"]
