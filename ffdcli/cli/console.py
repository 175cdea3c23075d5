"""What a command prints: text for people, one JSON object with ``--json``, nothing with ``-q``."""

from __future__ import annotations

import sys
from dataclasses import dataclass

from ffdcli.errors import FfdError
from ffdcli.io.jsontext import plain, to_json
from ffdcli.progress import ProgressFactory, terminal_progress


@dataclass
class Console:
    """What a command prints. ``comm`` is the run's communicator (:mod:`ffdcli.parallel.comm`); under
    ``mpiexec`` only rank 0 prints (messages, warnings, progress and the ``--json`` summary)."""

    quiet: bool = False
    verbose: bool = False
    json: bool = False
    comm: object = None

    def __post_init__(self):
        if self.comm is None:
            from ffdcli.parallel.comm import SerialComm

            self.comm = SerialComm()
        if not self.comm.is_root:
            self.quiet = True

    def say(self, text: str) -> None:
        """Normal output (stdout); silent with --quiet or --json."""
        if not (self.quiet or self.json):
            _print(text)

    def detail(self, text: str) -> None:
        """Extra output with --verbose (stderr, so --json stays parseable)."""
        if self.verbose and not self.quiet:
            print(text, file=sys.stderr, flush=True)

    def warn(self, text: str) -> None:
        """A warning on stderr (shown unless --quiet)."""
        if not self.quiet:
            print(f"ffd: warning: {text}", file=sys.stderr, flush=True)

    def result(self, summary: dict, text: str) -> None:
        """The command's summary: JSON with --json, else ``text``."""
        if self.json and self.comm.is_root:
            _print(to_json(summary))
        else:
            self.say(text)

    @property
    def progress(self) -> ProgressFactory:
        return terminal_progress(enabled=not (self.quiet or self.json))


class StdoutError(FfdError):
    """Standard output cannot be written (``> /dev/full``, a closed pipe): exit 1, one line on stderr."""


def _print(text: str) -> None:
    try:
        print(text, file=sys.stdout, flush=True)
    except BrokenPipeError:
        raise
    except OSError as e:
        raise StdoutError(f"cannot write the summary to standard output: {e.strerror or e}; every file "
                          "written by this run is complete", hint="check where stdout goes") from None


#: ``json.dumps(default=)`` of old callers; new code writes JSON with :func:`ffdcli.io.jsontext.to_json`.
jsonable = plain
