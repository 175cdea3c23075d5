"""The Python API refuses what the command line refuses, with ffd's InputError and the same words.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest_plugins = ["hostile"]        # the workspaces: fixtures ws, ws2


def test_api_refuses_what_the_cli_refuses(ws2):
    from ffdcli.api import DesignModel
    from ffdcli.errors import InputError

    model = DesignModel.from_file(ws2 / "good.yaml")
    v0 = model.values.copy()
    chord = [i for i, n in enumerate(model.names) if ".chord" in n]
    for bad in (np.nan, np.inf, -np.inf):
        v = v0.copy()
        v[0] = bad
        with pytest.raises(InputError, match=model.names[0].replace("[", r"\[").replace("]", r"\]")):
            model.set_values(v)
    for bad in (0.0, -1.0):
        v = v0.copy()
        v[chord[-1]] = bad
        with pytest.raises(InputError):
            model.set_values(v)
    assert np.array_equal(model.values, v0)              # unchanged after every refusal
    with pytest.raises(InputError):
        model.surface_jvp(np.ones(model.n_vars + 1))
    with pytest.raises(InputError):
        model.surface_vjp(np.ones((3, 3)))
    with pytest.raises(InputError, match="list of KEY=VALUE"):
        DesignModel.from_file(ws2 / "good.yaml", "changes.0.twist.tip=3")

