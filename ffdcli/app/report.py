"""What a command's workflow hands back to the command line: one frozen value.

Every workflow of a command (``app/``, and the ones that stand on a
:class:`~ffdcli.api.DesignModel` in :mod:`ffdcli.api.commands`) returns a report: the ``--json``
summary, the text a person reads, the warnings to print. The command line parses its options, calls
one workflow and prints the report; nothing else. Workflows with more to say have their own report
class (:class:`~ffdcli.app.deform.DeformReport`, :class:`~ffdcli.app.box.BoxReport`, ...) with at
least these three fields.
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class CommandReport:
    """summary: the ``--json`` object; text: the same for people; warnings: printed on stderr first."""

    summary: dict
    text: str
    warnings: tuple[str, ...] = field(default=())
