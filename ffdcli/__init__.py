"""ffd: automatic free-form deformation for aerodynamic design.

The folders are the stages of the data flow, in order; a stage imports only the ones before it::

    mesh/ -> parallel/ -> io/ (formats: read) -> geometry/ (surface, axes, sections)
      -> lattice/ (splines, embedding) -> box/ (the automatic lattice, cached)
      -> parameterization/ (changes on the lattice, derivatives) -> constraints/
      -> volume/ (the mesh follows) -> quality/ (the gate) -> io/ (formats: write)

``design/`` reads the design file, ``viz/`` draws, ``app/`` holds one workflow per command,
``api.py`` and ``openmdao.py`` are the objects an optimisation keeps, ``optimize/`` drives a flow
solver, and ``cli/`` only parses, calls ``app/`` and prints. ``docs/ARCHITECTURE.md`` has the map.
"""

from ffdcli import _compat

__version__ = "0.1.0"

_compat.install()
