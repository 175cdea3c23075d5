"""Imports every command module so that each registers itself on the ``ffd`` group.

Order here is the order in ``ffd --help``.
"""

from ffdcli.cli import inspect  # noqa: F401, I001  (order = order in --help)
from ffdcli.cli import check  # noqa: F401
