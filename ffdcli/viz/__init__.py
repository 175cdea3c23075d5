"""Pictures: 2D views (matplotlib) and the optional 3D view (pyvista)."""
