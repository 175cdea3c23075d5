"""The wing surface read off the mesh: surface points and normals, the detected axes, airfoil sections."""
