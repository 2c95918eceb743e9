"""A spatial N-link chain of any length, and a writer of robots as TOML.

:func:`n_link_chain` is the standing benchmark robot (derivation, generation
and compile time against N) and a source of random, physically realisable
arms for cross-checks.  :func:`chain_to_toml` writes any :class:`Robot` as a
robot file, so a user can start a new robot from a generated chain::

    python -m fmugen.robot.chain 6 --joints RRP --seed 1 > robots/my_arm.toml

Chain geometry (standard DH, link i = 1..N)
-------------------------------------------
* ``alpha_i`` cycles through ``pi/2, 0, -pi/2`` (exact), so consecutive joint
  axes are perpendicular, parallel, perpendicular: the chain is not planar;
* revolute joint: ``a_i = l_i``, ``d_i = 0.05 m``; prismatic joint: the same
  ``a_i`` and ``d_i = 0.1 m`` (the constant offset added to q_i);
* each link is a uniform rod of length ``l_i`` and radius ``r_i`` lying along
  ``-x_i`` from the frame-i origin: centre of mass ``(-l_i/2, 0, 0)``, inertia
  about it ``diag(m r^2/2, m(3r^2+l^2)/12, m(3r^2+l^2)/12)``.

Without ``seed`` the nominal values are ``l = 0.3 m``, ``r = 0.02 m``,
``m = 1 kg`` for every link.  With ``seed`` every link draws
``l in [0.1, 0.5] m``, ``r in [0.01, 0.05] m``, ``m in [0.5, 2] kg``, a centre
of mass displaced by up to 2 cm in each axis, and a random orientation of the
rod's principal axes (full inertia tensor, all products non-zero) -- always a
realisable rigid body.  Gravity is ``[0, 0, -9.81] m/s^2``.
"""
from __future__ import annotations

import argparse
import sys

import numpy as np
import sympy as sp
from sympy.printing.str import StrPrinter

from .checks import inertia_problems, numeric, numeric_matrix
from .description import PRISMATIC, REVOLUTE, Link, Robot
from .loader import robot_from_toml

ALPHA_CYCLE = (sp.pi / 2, sp.Integer(0), -sp.pi / 2)
GRAVITY = (0.0, 0.0, -9.81)


def joint_pattern(n: int, joint_types: str = "R") -> str:
    """The joint letters of an n-link chain: ``"R"``, ``"P"`` or a pattern
    such as ``"RRP"`` repeated cyclically to length n."""
    letters = joint_types.upper()
    if not letters or set(letters) - {"R", "P"}:
        raise ValueError(f"joint_types must be a string of 'R' and 'P', got {joint_types!r}")
    if n < 1:
        raise ValueError(f"a chain needs at least one link, got n={n}")
    return (letters * (n // len(letters) + 1))[:n]


def n_link_chain(n: int, joint_types: str = "R", symbolic: bool = False, seed=None) -> Robot:
    """An n-link spatial serial chain (see the module docstring for its geometry).

    Parameters
    ----------
    n : number of links (>= 1).
    joint_types : ``"R"``, ``"P"`` or a pattern like ``"RRP"`` (repeated).
    symbolic : False: the numbers are built into the description (no
        parameters, the fastest to derive).  True: every non-zero length,
        mass, COM and inertia entry is a named parameter with the number as
        its default, exactly as if the chain were read from a robot file.
    seed : None for the nominal values, else a seed for random realisable
        values (``numpy.random.default_rng(seed)``).

    >>> robot = n_link_chain(3, "RRP")
    >>> [link.joint for link in robot.links]
    ['revolute', 'revolute', 'prismatic']
    """
    pattern = joint_pattern(n, joint_types)
    rng = None if seed is None else np.random.default_rng(seed)
    links = tuple(_link(i, letter, rng) for i, letter in enumerate(pattern, start=1))
    kind = "random" if rng is not None else "nominal"
    robot = Robot(
        name=f"chain{n}_{pattern.lower()}" if n <= 12 else f"chain{n}",
        convention="standard",
        links=links,
        gravity=tuple(sp.Float(g) if g else sp.Integer(0) for g in GRAVITY),
        parameters=(),
        description=f"{n}-link spatial chain, joints {pattern}, {kind} values"
        + (f" (seed {seed})" if rng is not None else ""),
        source=f"<n_link_chain({n}, {joint_types!r}, seed={seed})>",
    )
    if symbolic:
        return robot_from_toml(chain_to_toml(robot), source=robot.source)
    return robot


def _link(i: int, letter: str, rng) -> Link:
    if rng is None:
        length, radius, mass = 0.3, 0.02, 1.0
        offset = np.zeros(3)
        rotation = np.eye(3)
    else:
        length = rng.uniform(0.1, 0.5)
        radius = rng.uniform(0.01, 0.05)
        mass = rng.uniform(0.5, 2.0)
        offset = rng.uniform(-0.02, 0.02, size=3)
        rotation = _random_rotation(rng)
    side = mass * (3 * radius**2 + length**2) / 12
    principal = np.diag([mass * radius**2 / 2, side, side])
    inertia = rotation @ principal @ rotation.T
    inertia = 0.5 * (inertia + inertia.T)  # exactly symmetric in floating point
    com = np.array([-length / 2, 0.0, 0.0]) + offset
    prismatic = letter == "P"

    def num(x):
        return sp.Integer(0) if x == 0 else sp.Float(float(x))

    return Link(
        name=f"link{i}",
        joint=PRISMATIC if prismatic else REVOLUTE,
        a=num(length),
        alpha=ALPHA_CYCLE[(i - 1) % 3],
        d=num(0.1 if prismatic else 0.05),
        theta=sp.Integer(0),
        mass=num(mass),
        com=tuple(num(c) for c in com),
        inertia_com=tuple(tuple(num(inertia[r, c]) for c in range(3)) for r in range(3)),
    )


def _random_rotation(rng) -> np.ndarray:
    """A uniformly random proper rotation (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


# ---------------------------------------------------------------- TOML writer
class _FilePrinter(StrPrinter):
    """Prints sympy expressions in the robot-file expression language."""

    def _print_Abs(self, expr):
        return f"abs({self._print(expr.args[0])})"

    def _print_Exp1(self, expr):
        return "exp(1)"

    def _print_Float(self, expr):
        return repr(float(expr))


def _toml_value(expr) -> str:
    expr = sp.sympify(expr)
    if expr.is_Integer:
        return str(int(expr))
    if expr.is_Float:
        return repr(float(expr))
    return '"' + _FilePrinter().doprint(expr) + '"'


def _toml_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def chain_to_toml(robot: Robot) -> str:
    """A robot file (TOML text) describing ``robot``; loading it gives the same robot.

    Works for any :class:`Robot`, not only chains.  A parameter whose name is
    the automatic name of the one field it appears in (``m_2`` as the mass of
    link 2) is written as its number, so loading re-creates it; every other
    symbol is declared in ``[parameters]`` with its value, unit and
    description.  Inertia is written about the centre of mass.
    """
    if not robot.links:
        raise ValueError(f"{robot.name}: written as joints (URDF), not in DH parameters; "
                         "write it with fmugen.robot.urdf_export.robot_to_urdf (fmugen export-urdf)")
    fields = []  # (auto name, expression) in file order, to decide how to write each
    fields += [(f"g_{ax}", g) for ax, g in zip("xyz", robot.gravity)]
    for i, link in enumerate(robot.links, start=1):
        fields += [(f"a_{i}", link.a), (None, link.alpha), (f"d_{i}", link.d), (None, link.theta),
                   (f"m_{i}", link.mass), (f"Ia_{i}", link.rotor_inertia), (f"b_{i}", link.damping)]
        fields += [(f"rc_{i}_{ax}", c) for ax, c in zip("xyz", link.com)]
        for r, c, ax in ((0, 0, "xx"), (1, 1, "yy"), (2, 2, "zz"), (0, 1, "xy"), (0, 2, "xz"), (1, 2, "yz")):
            fields.append((f"I_{i}_{ax}", link.inertia_com[r][c]))
    if robot.payload is not None:
        fields.append(("m_L", robot.payload.mass))
        fields += [(f"rc_L_{ax}", c) for ax, c in zip("xyz", robot.payload.com)]

    uses = {}
    for _, e in fields:
        for s in sp.sympify(e).free_symbols:
            uses[s.name] = uses.get(s.name, 0) + 1
    by_name = {p.name: p for p in robot.parameters}
    inline = set()  # auto-named parameters written as plain numbers
    for auto, e in fields:
        e = sp.sympify(e)
        p = by_name.get(e.name) if isinstance(e, sp.Symbol) else None
        if p is not None and p.name == auto and p.value is not None and uses[p.name] == 1:
            inline.add(p.name)

    def value(expr, auto=None):
        expr = sp.sympify(expr)
        if isinstance(expr, sp.Symbol) and expr.name in inline and expr.name == auto:
            return repr(float(by_name[expr.name].value))
        return _toml_value(expr)

    title = (robot.description or robot.name).replace("\n", "\n# ")
    out = [f"# {title}", "# Written by fmugen.robot.chain.chain_to_toml.", ""]
    out += ["[robot]", f"name = {_toml_string(robot.name)}"]
    if robot.description:
        out.append(f"description = {_toml_string(robot.description)}")
    out.append(f"convention = {_toml_string(robot.convention)}")
    out.append("gravity = [" + ", ".join(value(g, f"g_{ax}") for ax, g in zip("xyz", robot.gravity)) + "]  # m/s^2, base frame")
    declared = [n for n in uses if n not in inline]
    if declared:
        out += ["", "[parameters]"]
        for n in declared:
            p = by_name.get(n)
            items = []
            if p is not None and p.value is not None:
                items.append(f"value = {float(p.value)!r}")
            if p is not None and p.unit:
                items.append(f"unit = {_toml_string(p.unit)}")
            if p is not None and p.description:
                items.append(f"description = {_toml_string(p.description)}")
            out.append(f"{n} = {{ {', '.join(items)} }}")
    for i, link in enumerate(robot.links, start=1):
        out += ["", "[[links]]", f"name = {_toml_string(link.name)}", f"joint = {_toml_string(link.joint)}"]
        out.append(f"a = {value(link.a, f'a_{i}')}  # m")
        out.append(f"alpha = {value(link.alpha)}  # rad")
        out.append(f"d = {value(link.d, f'd_{i}')}  # m")
        out.append(f"theta = {value(link.theta)}  # rad")
        out.append(f"mass = {value(link.mass, f'm_{i}')}  # kg")
        out.append("com = [" + ", ".join(value(c, f"rc_{i}_{ax}") for ax, c in zip("xyz", link.com)) + f"]  # m, frame {i}")
        names = (("xx", "xy", "xz"), ("xy", "yy", "yz"), ("xz", "yz", "zz"))
        rows = ["[" + ", ".join(value(link.inertia_com[r][c], f"I_{i}_{names[r][c]}") for c in range(3)) + "]"
                for r in range(3)]
        out.append("inertia = [" + ", ".join(rows) + "]  # kg m^2 about the COM, frame-i axes")
        out.append('inertia_about = "com"')
        if link.rotor_inertia != 0:
            out.append(f"rotor_inertia = {value(link.rotor_inertia, f'Ia_{i}')}")
        if link.damping != 0:
            out.append(f"damping = {value(link.damping, f'b_{i}')}")
        if link.external_wrench:
            out.append("external_wrench = true")
        if not _realisable(link, robot.parameter_values()):
            out.append("allow_unrealisable_inertia = true  # as in the robot this file was written from")
    if robot.payload is not None:
        out += ["", "[payload]", f"mass = {value(robot.payload.mass, 'm_L')}  # kg"]
        out.append("com = [" + ", ".join(value(c, f"rc_L_{ax}") for ax, c in zip("xyz", robot.payload.com)) + "]  # m, last link frame")
    return "\n".join(out) + "\n"


def _realisable(link: Link, values: dict) -> bool:
    m = numeric(link.mass, values)
    I = numeric_matrix(link.inertia_com, values)
    return m is None or I is None or not inertia_problems(m, I)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m fmugen.robot.chain",
        description="Write an N-link spatial chain as a robot file (TOML) on standard output.",
    )
    parser.add_argument("n", type=int, help="number of links")
    parser.add_argument("--joints", default="R", help="'R', 'P' or a pattern such as 'RRP' (repeated)")
    parser.add_argument("--seed", type=int, default=None, help="random realisable values from this seed")
    args = parser.parse_args(argv)
    sys.stdout.write(chain_to_toml(n_link_chain(args.n, args.joints, seed=args.seed)))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
