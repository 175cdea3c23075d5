"""Cached products invalidated by the hash of what they depend on (trimesh's ``caching.py`` idea).

A stage keeps one :class:`Memo` per product (the lattices of some design values, the frames of some
lattices, ...): asked with the digest of its inputs, it recomputes only when the digest differs from
the one it holds. Nothing is cleared by hand; a product of other inputs simply replaces it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numpy as np


def digest(*items) -> bytes:
    """The hash of arrays (and sequences of arrays, scalars, strings): dtype, shape and bytes of each."""
    h = hashlib.blake2b(digest_size=16)

    def feed(x):
        if isinstance(x, (list, tuple)):
            h.update(b"(%d" % len(x))
            for y in x:
                feed(y)
            h.update(b")")
        elif isinstance(x, str):
            h.update(b"s" + x.encode())
        elif x is None:
            h.update(b"N")
        else:
            a = np.ascontiguousarray(x)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())

    for item in items:
        feed(item)
    return h.digest()


class Memo:
    """One cached product: the last value and the digest of the inputs it was computed from."""

    __slots__ = ("_key", "_value")

    def __init__(self):
        self._key: bytes | None = None
        self._value = None

    def get(self, key: bytes, compute: Callable[[], object]):
        """The product for inputs of digest ``key``: the one held, or ``compute()`` (then held)."""
        if self._key != key:
            value = compute()
            self._key, self._value = key, value
        return self._value


class Once:
    """A product of the stage's fixed data (the baseline, the mesh): computed on first use, kept."""

    __slots__ = ("_done", "_value")

    def __init__(self):
        self._done = False
        self._value = None

    def get(self, compute: Callable[[], object]):
        if not self._done:
            self._value = compute()
            self._done = True
        return self._value
