"""Design variables: the changes (twist, span, sweep, dihedral, chord, shape), bounds, derivatives
dP/dv, components, the airfoil fit.
"""
