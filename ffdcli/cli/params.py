"""Click types of ffd's options: numbers that must be finite (``nan`` and ``inf`` parse as floats, and
``FloatRange(min=0)`` lets ``nan`` through: every comparison with it is false)."""

from __future__ import annotations

import math

import click


class FiniteFloat(click.FloatRange):
    """A finite float, optionally within a range (click's ``FloatRange`` arguments)."""

    name = "finite float"

    def convert(self, value, param, ctx):
        number = click.FLOAT.convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"expected a finite number, got {value!r}", param, ctx)
        return super().convert(number, param, ctx)


#: Any finite float.
FINITE = FiniteFloat()
