"""Design variables: the changes (twist, span, sweep, dihedral, chord, shape, flap, slat), bounds, derivatives
dP/dv, components, the airfoil fit.
"""
