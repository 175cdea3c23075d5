"""The errors a user sees.

Library code raises :class:`InputError` (exit 2) for anything wrong with what the user gave us
(a file, a key, a value) and :class:`QualityError` (exit 3) when a deformed mesh fails the quality
check. Messages are one line, name the file (and the key path or line) and say what was expected.
Any other exception is a bug in ffd: the command line reports it in one line with exit 1.
"""

from __future__ import annotations

from pathlib import Path


class FfdError(Exception):
    """Base class of the errors that the command line reports without a traceback."""

    exit_code = 1

    def __init__(self, message: str, *, path: str | Path | None = None, key: str | None = None,
                 line: int | None = None, hint: str | None = None):
        self.message = message
        self.path = None if path is None else str(path)
        self.key = key
        self.line = line
        self.hint = hint
        super().__init__(self.format())

    def format(self) -> str:
        where = ""
        if self.path:
            where = self.path
            if self.line is not None:
                where += f":{self.line}"
            where += ": "
        key = f"{self.key}: " if self.key else ""
        hint = f" ({self.hint})" if self.hint else ""
        return f"{where}{key}{self.message}{hint}"


class InputError(FfdError):
    """Bad input or usage: a missing/corrupt file, a wrong key or value. Exit status 2."""

    exit_code = 2


class QualityError(FfdError):
    """The deformed mesh failed the quality check; nothing was written. Exit status 3."""

    exit_code = 3

    def __init__(self, message: str, *, report: dict | None = None, **kw):
        self.report = report or {}
        super().__init__(message, **kw)
