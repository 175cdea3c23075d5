"""The one way an extension kind declares itself: :class:`Registry`.

A mesh format, a design change, a constraint and a flow solver are each a *kind* of their extension
point, and each declares itself the same way, in its own module (meshio's ``register_format`` at the
end of a format's module is the model)::

    kind                      the name the design file uses (``twist``, ``thickness``, ``su2``)
    schema() -> dict          the JSON-schema fragment of its YAML (a fresh dict on every call)
    from_spec(spec, context)  its object built from that YAML; ``context`` is what the extension point
                              hands every kind (the lattice, the baseline surface, the solver's config)

and the module ends with one line, ``CHANGES.register(Twist)``. The package of an extension point
imports every kind module in its ``__init__`` (its face), so that importing any part of it registers
them all; nothing else lists the kinds. :func:`ffdcli.design.schema.design_schema` (``ffd schema``)
is assembled from the registries.

A registry is filled while its package is imported and read afterwards; it refuses a second kind of
the same name, and lists its kinds sorted by name (so that no message or schema depends on the
order in which modules happen to be imported). Light: stdlib only.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Kind(Protocol):
    """What every registered kind has (a class with classmethods, or an instance)."""

    kind: str

    def schema(self) -> dict: ...

    def from_spec(self, spec: Any, context: Any) -> Any: ...


class Registry:
    """The kinds of one extension point (``what``: ``"change"``, ``"constraint"``, ...), by name."""

    def __init__(self, what: str):
        self.what = what
        self._kinds: dict[str, Any] = {}

    def register(self, entry):
        """Add ``entry`` (has ``kind``, ``schema()``, ``from_spec(spec, context)``) and return it (so it may
        decorate a class). A second entry of the same kind is a programming error (ValueError)."""
        kind = getattr(entry, "kind", None)
        if not isinstance(kind, str) or not kind:
            raise ValueError(f"a {self.what} kind needs a non-empty str 'kind', got {kind!r} on {entry!r}")
        for method in ("schema", "from_spec"):
            if not callable(getattr(entry, method, None)):
                raise ValueError(f"the {self.what} kind {kind!r} has no {method}()")
        if kind in self._kinds and self._kinds[kind] is not entry:
            raise ValueError(f"a second {self.what} kind named {kind!r} ({entry!r}; the first: {self._kinds[kind]!r})")
        self._kinds[kind] = entry
        return entry

    def kinds(self) -> tuple[str, ...]:
        """Every kind's name, sorted."""
        return tuple(sorted(self._kinds))

    def get(self, kind: str, default=None):
        return self._kinds.get(kind, default)

    def __getitem__(self, kind: str):
        return self._kinds[kind]

    def __contains__(self, kind: object) -> bool:
        return kind in self._kinds

    def __iter__(self) -> Iterator[str]:
        return iter(self.kinds())

    def __len__(self) -> int:
        return len(self._kinds)

    def schemas(self) -> dict[str, dict]:
        """{kind: its schema fragment}, sorted by kind."""
        return {kind: self._kinds[kind].schema() for kind in self.kinds()}

    def unknown(self, kind: str) -> str:
        """The words for a kind nobody registered: ``unknown constraint 'x'; the kinds are a, b``."""
        return f"unknown {self.what} {kind!r}; the kinds are {', '.join(self.kinds())}"

    def __repr__(self) -> str:
        return f"Registry({self.what!r}: {', '.join(self.kinds())})"
