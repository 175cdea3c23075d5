"""Progress reporting that the library can call without knowing about terminals.

Library functions take an optional ``progress`` argument: a factory ``progress(label, total)``
returning a bar with ``update(n)`` and ``close()`` (and usable as a context manager). The default,
:func:`no_progress`, does nothing; the command line passes :func:`terminal_progress` bars that draw
on stderr only when it is a terminal and the user did not ask for ``--quiet``/``--json``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Protocol

from ffdcli.deferred import deferred

tqdm = deferred("tqdm")      # imported when a bar is drawn on a terminal


class Bar(Protocol):
    def update(self, n: int = 1) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> Bar: ...
    def __exit__(self, *exc) -> None: ...


ProgressFactory = Callable[[str, int], Bar]


class _NullBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


def no_progress(label: str, total: int) -> Bar:
    """A progress factory that draws nothing."""
    return _NullBar()


def terminal_progress(enabled: bool = True, stream=None) -> ProgressFactory:
    """A factory of tqdm bars on ``stream`` (stderr), or of silent bars when not on a terminal."""
    stream = stream or sys.stderr
    show = enabled and hasattr(stream, "isatty") and stream.isatty()
    if not show:
        return no_progress

    def factory(label: str, total: int) -> Bar:
        return tqdm.tqdm(total=total, desc=label, file=stream, leave=False, unit_scale=True,
                         dynamic_ncols=True, mininterval=0.2)

    return factory


def chunks(n: int, size: int):
    """(start, stop) pairs covering range(n) in pieces of at most ``size``."""
    size = max(1, int(size))
    for start in range(0, n, size):
        yield start, min(n, start + size)
