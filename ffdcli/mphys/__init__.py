"""ffd inside MPhys: a geometry component with pyGeo's MPhys interface and an MPhys ``Builder``.

Needs the ``[mphys]`` extra (``pip install 'ffdcli[mphys]'``: MPhys 2 and OpenMDAO); docs/mphys.md.

>>> from ffdcli.mphys import FFDGeometry, FFDBuilder
>>> geometry = FFDGeometry(design="wing.yaml")        # in place of OM_DVGEOCOMP(file="ffd.xyz", type="ffd")
"""

from ffdcli.mphys.builder import FFDBuilder
from ffdcli.mphys.geometry import FFDGeometry, PointSetInfo
from ffdcli.mphys.names import DISCIPLINES, FFDNote, coordinate_names

__all__ = ["DISCIPLINES", "FFDBuilder", "FFDGeometry", "FFDNote", "PointSetInfo", "coordinate_names"]
