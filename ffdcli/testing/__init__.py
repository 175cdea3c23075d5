"""Fixtures for the samples, the tests and the benchmarks: not part of the FFD pipeline.

:mod:`ffdcli.testing.wings` makes NACA sections, planforms and parametric wing surfaces and meshes
(the bundled ``samples/`` are made from it by ``samples/make_samples.py``). The library never
imports this package.
"""
