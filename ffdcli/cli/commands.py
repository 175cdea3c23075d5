"""Imports every command module so that each registers itself on the ``ffd`` group.

Order here is the order in ``ffd --help``.
"""

from ffdcli.cli import inspect  # noqa: F401, I001
from ffdcli.cli import init  # noqa: F401, I001
from ffdcli.cli import box  # noqa: F401, I001
from ffdcli.cli import deform  # noqa: F401, I001
from ffdcli.cli import plot  # noqa: F401, I001
from ffdcli.cli import fit  # noqa: F401, I001
from ffdcli.cli import grad  # noqa: F401, I001
from ffdcli.cli import vars  # noqa: F401, I001
from ffdcli.cli import constraints  # noqa: F401, I001
from ffdcli.cli import optimize  # noqa: F401, I001
from ffdcli.cli import check  # noqa: F401, I001
from ffdcli.cli import schema  # noqa: F401, I001
