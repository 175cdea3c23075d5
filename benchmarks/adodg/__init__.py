"""ADODG Case 1 (the transonic NACA 0012 drag minimisation): its mesh family and baseline runs.

``python -m benchmarks.adodg.meshes --out DIR`` writes the nested O-grid family;
``python -m benchmarks.adodg.baseline --meshes DIR`` runs SU2 on each level and extrapolates CD;
``python -m benchmarks.adodg.surface BASE.su2 DESIGN.su2`` checks a design's add-material rule at every
airfoil node. The case and its sources: docs/adodg-case1.md.
"""
