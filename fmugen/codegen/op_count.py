"""Operation counts of generated code (:class:`OpCount`).

Its own module: the C printer (:mod:`fmugen.codegen.c_code`) counts the
printed C with it and the looped chain dynamics (:mod:`fmugen.codegen.chain`)
count the runtime's loops in the same units, and the printer imports the
chain -- with the class in either of the two, they imported each other.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass


@dataclass(frozen=True)
class OpCount:
    """Floating-point operations of a piece of straight-line C.

    Counting rules (applied to the printed C, token by token):

    * every binary ``*`` is one multiplication (so a product of k factors is
      k-1), including products with literals such as ``2.0*a``;
    * every binary ``+``/``-`` is one addition; a unary minus counts nothing
      (the compiler folds it into a neighbouring add/sub or flips a sign bit);
    * every ``/`` is one division (``1.0/sqrt(a)`` is one division and one
      call);
    * every call of a math function (``sin``, ``cos``, ``sqrt``, ``pow``, ...)
      is one call, also listed by name in ``calls``;
    * copies (``const double a = b;``, stores into the result arrays) are
      free.
    """

    mul: int = 0
    add: int = 0
    div: int = 0
    calls: tuple = ()  # sorted ((name, count), ...)

    @property
    def n_calls(self) -> int:
        return sum(n for _, n in self.calls)

    def __add__(self, other: "OpCount") -> "OpCount":
        c = Counter(dict(self.calls))
        c.update(dict(other.calls))
        return OpCount(self.mul + other.mul, self.add + other.add, self.div + other.div,
                       tuple(sorted(c.items())))

    def __str__(self) -> str:
        s = f"{self.mul} mul, {self.add} add, {self.div} div, {self.n_calls} call"
        if self.n_calls != 1:
            s += "s"
        if self.calls:
            s += " (" + ", ".join(f"{k} {n}" for k, n in self.calls) + ")"
        return s

    def as_dict(self) -> dict:
        return {"mul": self.mul, "add": self.add, "div": self.div, "calls": dict(self.calls)}
