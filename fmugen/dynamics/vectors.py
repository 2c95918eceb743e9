"""3-vector and 3x3 helpers that bind every result component in a Program.

Vectors are plain lists of three sympy expressions; matrices lists of three
rows.  Each helper returns components that are either trivial (0, a symbol)
or fresh program symbols, so expressions never grow beyond one step.
Structural zeros stay exact zeros because sympy folds ``0*x`` and ``x + 0``.
"""
from __future__ import annotations

import sympy as sp

from ..codegen.program import Program

ZERO3 = [sp.Integer(0)] * 3
EZ = [sp.Integer(0), sp.Integer(0), sp.Integer(1)]


def add(P: Program, a, b, hint=""):
    return [P.let(a[k] + b[k], hint) for k in range(3)]


def sub(P: Program, a, b, hint=""):
    return [P.let(a[k] - b[k], hint) for k in range(3)]


def scale(P: Program, s, a, hint=""):
    return [P.let(s * a[k], hint) for k in range(3)]


def cross(P: Program, a, b, hint=""):
    return [
        P.let(a[1] * b[2] - a[2] * b[1], hint),
        P.let(a[2] * b[0] - a[0] * b[2], hint),
        P.let(a[0] * b[1] - a[1] * b[0], hint),
    ]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def matvec(P: Program, R, v, hint=""):
    """R v."""
    return [P.let(dot(R[i], v), hint) for i in range(3)]


def matTvec(P: Program, R, v, hint=""):
    """R^T v."""
    return [P.let(R[0][i] * v[0] + R[1][i] * v[1] + R[2][i] * v[2], hint) for i in range(3)]


def matmul(P: Program, A, B, hint=""):
    return [[P.let(sum(A[i][k] * B[k][j] for k in range(3)), hint) for j in range(3)] for i in range(3)]


def is_zero(v) -> bool:
    return all(sp.sympify(c) == 0 for c in v)
