"""ffd: automatic free-form deformation for aerodynamic design.

Data flows one way through the package::

    formats (mesh I/O) -> surface -> axes -> box (automatic lattice) -> embedding (cached)
      -> changes (design on the lattice) -> embedding.displace (B @ dP) -> warp (volume follows)
      -> quality (check) -> formats (write)

The command line (`ffdcli.cli`) is a thin layer over these modules; everything is usable from Python.
"""

__version__ = "0.1.0"
