"""A design file as the output of a command (``ffd init``, ``ffd fit``): the one rule for both.

A design file is what a user edits by hand, so an existing one is never replaced without ``--force``
(``ffd deform`` replaces its meshes freely: a ``--set`` loop writes them again and again). The file
is planned like every other output (:func:`ffdcli.io.outputs.plan_outputs`: a ``.yaml`` name, a
writable folder, never an input of the run) before any work, and written whole or not at all; a
failed write (a full disk, a file-size limit, a read-only file system) is one line naming the file.
"""

from __future__ import annotations

import os
from pathlib import Path

from ffdcli.errors import InputError
from ffdcli.io.inputs import existing_kind
from ffdcli.io.outputs import OutputPlan, plan_outputs


def plan_design_output(path, *, inputs=(), force: bool = False, option: str = "-o") -> OutputPlan:
    """The plan of a design file written at ``path`` (kind ``design``), checked before the work.

    Raises InputError (exit 2) when a file is there already and ``force`` is not given, naming
    ``--force`` and ``option`` as the ways out."""
    p = Path(path)
    plan = plan_outputs([("design", p, False, option)], inputs=inputs)
    if existing_kind(p) is not None and not force:
        raise InputError(f"the design file exists (hand edits would be lost); pass --force to replace it, "
                         f"or {option} another name", path=p)
    return plan


def write_design_text(plan: OutputPlan, text: str) -> str:
    """Write ``text`` as the planned design file, whole or not at all; returns its path."""

    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())      # a full disk shows here, not after the rename

    return plan.write({"design": write})["design"]
