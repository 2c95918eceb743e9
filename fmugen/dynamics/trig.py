"""One sin and one cos per joint angle, shared by everything derived in a Program."""
from __future__ import annotations

import sympy as sp

from ..codegen.program import Program


class TrigCache:
    """Binds cos(angle) and sin(angle) once per distinct angle expression.

    Angles that are exact numbers (alpha = -pi/2) are not bound: sympy gives
    exact values, so structural zeros and ones stay in the algebra.
    """

    def __init__(self, program: Program):
        self.program = program
        self._cache: dict = {}

    def cos_sin(self, angle) -> tuple:
        angle = sp.sympify(angle)
        if angle.is_number:
            return sp.cos(angle), sp.sin(angle)
        if angle not in self._cache:
            P = self.program
            self._cache[angle] = (P.let(sp.cos(angle), "c"), P.let(sp.sin(angle), "s"))
        return self._cache[angle]
