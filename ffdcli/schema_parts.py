"""JSON-schema building blocks every kind's fragment is made of (light: no imports).

The kinds (:mod:`ffdcli.registry`) each write the fragment of their own YAML with these, and
:mod:`ffdcli.design.schema` assembles the design file's schema from the fragments. Every function
returns a fresh dict.
"""

from __future__ import annotations


def number() -> dict:
    return {"type": "number"}


def positive() -> dict:
    return {"type": "number", "exclusiveMinimum": 0}


def number_list() -> dict:
    return {"type": "array", "items": number(), "minItems": 1}


def positive_list() -> dict:
    return {"type": "array", "items": positive(), "minItems": 1}


def marker_names() -> dict:
    return {"anyOf": [{"type": "string", "minLength": 1},
                      {"type": "array", "items": {"type": "string", "minLength": 1}, "minItems": 1}],
            "description": "a marker name or a list of marker names"}


def root_tip(value: dict) -> dict:
    """``{tip: value}`` or ``{root: value, tip: value}``."""
    return {"type": "object", "properties": {"root": value, "tip": value}, "required": ["tip"],
            "additionalProperties": False}


def fraction() -> dict:
    """A number in [0, 1] (a chord or span fraction)."""
    return {"type": "number", "minimum": 0, "maximum": 1}
