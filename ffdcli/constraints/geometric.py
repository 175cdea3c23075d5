"""Deprecated path: the constraints are now one module per kind (:mod:`ffdcli.constraints`); import
from ``ffdcli.constraints`` (or its modules). This alias goes in the next release."""

import warnings

from ffdcli.constraints import *  # noqa: F403 - the names this module offered
from ffdcli.constraints import __all__  # noqa: F401

warnings.warn("ffdcli.constraints.geometric has moved to ffdcli.constraints (one module per kind); "
              "the old path goes in the next release", DeprecationWarning, stacklevel=2)
