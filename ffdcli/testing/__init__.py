"""Public fixtures for the samples, the tests, the benchmarks and the examples: not part of the FFD pipeline.

Shipped in the wheel so that ``examples/`` and ``benchmarks/`` run from an installed ffd; nothing in
the pipeline imports them. Every module imports without gmsh (it is imported only inside
:func:`ffdcli.testing.gmsh_wings.fluid_tets`, from the ``[test]`` or ``[samples]`` extra):

- :mod:`~ffdcli.testing.naca`, :mod:`~ffdcli.testing.planform`: NACA sections and parametric wings in
  closed form (exact geometry oracles);
- :mod:`~ffdcli.testing.wings`: wing surfaces and a small hexahedral wing, and the face that
  re-exports the NACA, planform, O-grid and cell fixtures;
- :mod:`~ffdcli.testing.ogrid`: 2D O-grids around an airfoil; :mod:`~ffdcli.testing.cells`: signed
  cell volumes and areas;
- :mod:`~ffdcli.testing.gmsh_wings`: the one gmsh generator of tetrahedral wing meshes (the bundled
  ``samples/`` via ``samples/make_samples.py``, the tests, ``benchmarks/bench_robustness.py``), with
  boundary-layer prisms from :mod:`~ffdcli.testing.prisms`;
- :mod:`~ffdcli.testing.threadcomm`: ranks as threads of one process (MPI collectives without mpiexec).
"""
