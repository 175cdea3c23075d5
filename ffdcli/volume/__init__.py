"""The volume mesh follows the surface: IDW warp, marker roles, source tree, frame rotations, recovery."""
