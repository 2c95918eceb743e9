"""Read a robot file (TOML) into an immutable :class:`~fmugen.robot.description.Robot`.

The schema is documented field by field in ``robots/README.md``.  In short::

    [robot]       name, gravity (required); description, source, convention,
                  allow_unrealisable_inertia
    [parameters]  name = value | { value, unit, description }
    [[links]]     joint, a, alpha, d, theta, mass, com, inertia | gyration_sq
                  (required); name, inertia_about, rotor_inertia, damping,
                  friction, friction_velocity, limits, external_wrench,
                  allow_unrealisable_inertia
    [payload]     mass, com

Conversion to the canonical description
---------------------------------------
* Quantities are parsed by :mod:`fmugen.robot.expressions` (never evaluated).
* Every non-zero *numeric* quantity (a number, or a string without symbols)
  given for a length, mass, centre-of-mass component, inertia component,
  squared radius of gyration, rotor inertia, damping, gravity component or
  payload becomes a :class:`Parameter` with an automatic name (``a_2``,
  ``m_2``, ``rc_2_x``, ``I_2_xy``, ``k2_2_zz``, ``Ia_2``, ``b_2``, ``g_z``,
  ``m_L``, ``rc_L_x``; i is the 1-based link index) and the number as its
  default value, so FMUs can expose it.  Zeros stay exact structural zeros.
  DH angles (alpha, theta) stay exact constants (they are structure).
* ``Link.inertia_com`` is always the tensor about the centre of mass in the
  link-frame axes.  Data given about the link-frame origin are moved with the
  parallel-axis theorem ``I_c = I_o - m (|r|^2 E - r r^T)`` (r: COM, m: mass).
  ``gyration_sq = [kxx2, kyy2, kzz2]`` means ``I = m diag(kxx2, kyy2, kzz2)``
  about the stated point, products of inertia zero.
"""
from __future__ import annotations

import difflib
import tomllib
import warnings
from pathlib import Path

import sympy as sp

from .checks import (
    RobotFileError,
    singular_joint,
    unit_problem,
    UnrealisableInertiaWarning,
    check_nonnegative,
    check_symmetric,
    inertia_problems,
    numeric,
    numeric_matrix,
    where,
)
from .description import MODIFIED, PRISMATIC, REVOLUTE, STANDARD, Limits, Link, Parameter, Payload, Robot
from .expressions import ExpressionError, NAME_PATTERN, check_double, quantity, snap_angle, symbol_name_problem
from ..errors import MAX_IDENTIFIER_LENGTH, InputFileError, read_text_file, toml_problem

TOP_KEYS = {"robot": True, "parameters": False, "links": True, "payload": False}
ROBOT_KEYS = {
    "name": True,
    "gravity": True,
    "description": False,
    "source": False,
    "convention": False,
    "allow_unrealisable_inertia": False,
}
LINK_KEYS = {
    "joint": True,
    "a": True,
    "alpha": True,
    "d": True,
    "theta": True,
    "mass": True,
    "com": True,
    "inertia": False,
    "gyration_sq": False,
    "name": False,
    "inertia_about": False,
    "rotor_inertia": False,
    "damping": False,
    "friction": False,
    "friction_velocity": False,
    "limits": False,
    "external_wrench": False,
    "allow_unrealisable_inertia": False,
    "massless": False,
}
PAYLOAD_KEYS = {"mass": True, "com": True}
PARAMETER_KEYS = {"value": False, "unit": False, "description": False}
JOINTS = (REVOLUTE, PRISMATIC)
CONVENTIONS = (STANDARD, MODIFIED)
AXES = "xyz"
PAIRS = ((0, 0, "xx"), (1, 1, "yy"), (2, 2, "zz"), (0, 1, "xy"), (0, 2, "xz"), (1, 2, "yz"))


def is_urdf(path) -> bool:
    """A URDF (or xacro) file, by its name: ``.urdf``, ``.xacro``."""
    name = Path(path).name.lower()
    return name.endswith((".urdf", ".xacro"))


def load_robot_description(path, mimic: str = "independent", armature: dict | None = None) -> Robot:
    """Read, check and convert the robot file at ``path`` (TOML, or URDF: :mod:`fmugen.robot.urdf`).

    Raises :class:`RobotFileError` naming the file, link and field of the
    first problem found; warns (:class:`UnrealisableInertiaWarning`) for an
    unrealisable inertia the file explicitly allows.
    """
    if armature and not is_urdf(path):
        raise RobotFileError(f"{path}: armature is for URDF robots; a TOML robot gives each joint's "
                             f"rotor_inertia in its file")
    path = Path(path)
    if is_urdf(path):
        from .urdf import load_urdf

        return load_urdf(path, mimic=mimic, armature=armature)
    try:
        text = read_text_file(path, "robot file")
    except InputFileError as exc:
        raise RobotFileError(str(exc)) from None
    return robot_from_toml(text, source=str(path))


def robot_from_toml(text: str, source: str = "<string>") -> Robot:
    """Like :func:`load_robot_description` for TOML text; ``source`` names it in messages."""
    try:
        data = tomllib.loads(text)
    except (tomllib.TOMLDecodeError, RecursionError) as exc:
        raise RobotFileError(f"{source}: " + (toml_problem(exc) if isinstance(exc, RecursionError)
                             else f"TOML syntax error: {exc}")) from None
    return _Reader(source).robot(data)


class _Reader:
    """Turns the parsed TOML tables into a Robot, collecting parameters."""

    def __init__(self, source: str):
        self.file = source
        self.declared: dict[str, Parameter] = {}  # [parameters], in file order
        self.auto: dict[str, Parameter] = {}  # auto-named numbers, in file order
        self.auto_origin: dict[str, str] = {}  # auto name -> location that made it
        self.values: dict = {}  # symbol -> default value, for the checks
        self.user_names: set = set()  # every symbol name written in the file

    # ------------------------------------------------------------------ top
    def robot(self, data: dict) -> Robot:
        self._keys(data, TOP_KEYS, self.file)
        head = self._table(data["robot"], "[robot]")
        self._keys(head, ROBOT_KEYS, where(self.file, field="[robot]"))
        name = self._string(head["name"], "[robot]: name")
        if not NAME_PATTERN.match(name) or len(name) > MAX_IDENTIFIER_LENGTH:
            raise RobotFileError(
                f"{self.file}: [robot]: name: {name[:80]!r} is not an identifier of at most "
                f"{MAX_IDENTIFIER_LENGTH} characters (it becomes the FMU model identifier and a file name)"
            )
        convention = self._choice(head.get("convention", STANDARD), CONVENTIONS, "[robot]: convention")
        self.convention = convention
        allow_all = self._bool(head.get("allow_unrealisable_inertia", False), "[robot]: allow_unrealisable_inertia")
        text = self._string(head.get("description", ""), "[robot]: description")
        provenance = self._string(head.get("source", ""), "[robot]: source")
        if provenance:
            text = f"{text}\nSource: {provenance}" if text else f"Source: {provenance}"

        self._declare_parameters(data.get("parameters", {}))
        gravity = self._vector(head["gravity"], where(self.file, field="[robot]: gravity"), "g_{}", "m/s2",
                               "gravitational acceleration, {} component in the base frame")

        links_data = data["links"]
        if not isinstance(links_data, list) or not links_data:
            raise RobotFileError(f"{self.file}: links: at least one [[links]] table is required")
        links = tuple(self._link(i, t, allow_all) for i, t in enumerate(links_data, start=1))
        names = [link.name for link in links]
        for i, n in enumerate(names, start=1):
            if names.index(n) != i - 1:
                raise RobotFileError(f"{where(self.file, i, n, 'name')}: duplicate link name (also link {names.index(n) + 1})")

        payload = self._payload(data["payload"]) if "payload" in data else None
        self._check_well_posed(links, payload)
        parameters = self._parameters(links, gravity, payload)
        return Robot(
            name=name,
            convention=convention,
            links=links,
            gravity=gravity,
            parameters=parameters,
            payload=payload,
            description=text,
            source=self.file,
        )

    # ----------------------------------------------------------- parameters
    def _declare_parameters(self, table) -> None:
        table = self._table(table, "[parameters]")
        for name, spec in table.items():
            loc = where(self.file, field=f"[parameters]: {name}")
            problem = symbol_name_problem(name)
            if problem:
                raise RobotFileError(f"{loc}: invalid parameter name: {problem}")
            unit = description = ""
            value = None
            if isinstance(spec, dict):
                self._keys(spec, PARAMETER_KEYS, loc)
                unit = self._string(spec.get("unit", ""), f"[parameters]: {name}: unit")
                description = self._string(spec.get("description", ""), f"[parameters]: {name}: description")
                raw = spec.get("value")
            else:
                raw = spec
            if raw is not None:
                expr = self._parse(raw, loc + ": value")
                if expr.free_symbols:
                    raise RobotFileError(f"{loc}: value: must be a number, got {raw!r}")
                value = self._double(expr, raw, loc + ": value")
            if unit:
                self._unit(unit, loc + ": unit")
            symbol = sp.Symbol(name, real=True)
            self.declared[name] = Parameter(name, symbol, value, unit, description)
            if value is not None:
                self.values[symbol] = value

    def _parameters(self, links, gravity, payload) -> tuple:
        exprs = list(gravity)
        for link in links:
            exprs += [link.a, link.alpha, link.d, link.theta, link.mass, link.rotor_inertia, link.damping,
                      link.friction, link.friction_velocity]
            exprs += list(link.com) + [e for row in link.inertia_com for e in row]
        if payload is not None:
            exprs += [payload.mass, *payload.com]
        used = set().union(*(sp.sympify(e).free_symbols for e in exprs))
        used_names = {s.name for s in used}
        user_names = used_names - set(self.auto)
        clashes = [n for n in self.auto if n in self.user_names or n in self.declared]
        if clashes:
            n = clashes[0]
            raise RobotFileError(
                f"{self.auto_origin[n]}: the automatic parameter name {n!r} of this number clashes "
                f"with the user symbol {n!r}; rename the symbol"
            )
        unused = [n for n in self.declared if n not in used_names]
        if unused:
            warnings.warn(f"{self.file}: [parameters]: declared but not used: {', '.join(unused)}", stacklevel=4)
        params = [self.declared[n] for n in self.declared if n in used_names]
        params += [Parameter(n, sp.Symbol(n, real=True), None) for n in sorted(user_names - set(self.declared))]
        params += list(self.auto.values())
        assert {p.name for p in params} == used_names, "every free symbol is a parameter"
        return tuple(params)

    def _auto_parameter(self, expr, name: str, unit: str, description: str, loc: str):
        """A symbol for a non-zero numeric ``expr``; zeros and expressions pass through."""
        if expr.free_symbols:
            return expr
        if expr == 0:
            return sp.Integer(0)
        value = self._double(expr, expr, loc)
        symbol = sp.Symbol(name, real=True)
        self.auto[name] = Parameter(name, symbol, value, unit, description)
        self.auto_origin[name] = loc
        self.values[symbol] = value
        return symbol

    # ---------------------------------------------------------------- links
    def _link(self, i: int, table, allow_all: bool) -> Link:
        table = self._table(table, f"links[{i}]")
        name = table.get("name", f"link{i}")
        loc0 = where(self.file, i, name if isinstance(name, str) else None)
        self._keys(table, LINK_KEYS, loc0)
        name = self._string(name, None, loc0 + ": name")
        if not NAME_PATTERN.match(name):
            raise RobotFileError(f"{loc0}: name: {name!r} is not an identifier")
        label = f"link {i} ({name})"

        def loc(field):
            return where(self.file, i, name, field)

        joint = self._choice(table["joint"], JOINTS, None, loc("joint"))
        prismatic = joint == PRISMATIC

        def number(field, auto, unit, what, angle=False, nonnegative=False):
            expr = self._parse(table[field], loc(field)) if field in table else sp.Integer(0)
            self._check_unit(expr, unit, loc(field))
            if angle:
                return snap_angle(expr)
            if nonnegative:
                check_nonnegative(expr, self.values, loc(field), what.split(" of ")[0], unit)
            return self._auto_parameter(expr, auto, unit, f"{what} of {label}", loc(field))

        preceding = " (modified DH: a_{i-1}, before joint i)" if self.convention == MODIFIED else ""
        a = number("a", f"a_{i}", "m", "DH link length a" + preceding)
        alpha = number("alpha", None, "rad", "", angle=True)
        d_what = "constant offset added to the joint displacement" if prismatic else "DH link offset d"
        d = number("d", f"d_{i}", "m", d_what)
        theta = number("theta", None, "rad", "", angle=True)
        mass = number("mass", f"m_{i}", "kg", "mass", nonnegative=True)
        com = self._vector(table["com"], loc("com"), f"rc_{i}_" + "{}", "m",
                           "centre of mass, {} in frame " + f"{i}, of {label}")
        rotor_unit = "kg" if prismatic else "kg.m2"
        rotor = number("rotor_inertia", f"Ia_{i}", rotor_unit, "rotor (actuator) inertia", nonnegative=True)
        damping_unit = "N.s/m" if prismatic else "N.m.s/rad"
        damping = number("damping", f"b_{i}", damping_unit, "viscous joint damping", nonnegative=True)
        friction, friction_velocity = self._friction(table, i, prismatic, number, loc)
        limits = self._limits(table, prismatic, loc)
        wrench = self._bool(table.get("external_wrench", False), None, loc("external_wrench"))
        allow = allow_all or self._bool(table.get("allow_unrealisable_inertia", False), None,
                                        loc("allow_unrealisable_inertia"))

        massless = self._bool(table.get("massless", False), None, loc("massless"))
        m_value = numeric(mass, self.values)
        if m_value is not None and m_value == 0 and not massless:
            raise RobotFileError(
                f"{loc('mass')}: zero mass; a link must have a positive mass, or say massless = true "
                "(then its inertia must be zero and the joints it carries must still move some "
                "mass, inertia or rotor)")
        if massless and (m_value is None or m_value != 0):
            raise RobotFileError(f"{loc('massless')}: massless = true but mass = {table['mass']!r}; "
                                 "a massless link has mass = 0")
        inertia_com = self._inertia(table, i, label, mass, com, loc)
        field = "gyration_sq" if "gyration_sq" in table else "inertia"
        self._check_body(mass, inertia_com, allow, loc(field), label)
        return Link(
            name=name,
            joint=joint,
            a=a,
            alpha=alpha,
            d=d,
            theta=theta,
            mass=mass,
            com=com,
            inertia_com=tuple(tuple(inertia_com.row(r)) for r in range(3)),
            rotor_inertia=rotor,
            damping=damping,
            external_wrench=wrench,
            friction=friction,
            friction_velocity=friction_velocity,
            limits=limits,
        )

    def _friction(self, table, i, prismatic, number, loc) -> tuple:
        """``(F_c, v_c)`` of the link's joint: Coulomb friction ``friction`` (parameter ``fc_i``), smooth as
        F_c tanh(qd / v_c) with ``friction_velocity`` (``vc_i``) or, when not given, the robot-wide
        ``v_coulomb`` = 0.01 rad/s or m/s (as URDF robots).  With ``friction="stick-slip"`` the state-space
        model replaces the smooth term by stick and slip modes (robots/README.md)."""
        unit = "N" if prismatic else "N.m"
        friction = number("friction", f"fc_{i}", unit, "Coulomb joint friction", nonnegative=True)
        speed = "m/s" if prismatic else "rad/s"
        if "friction_velocity" in table:
            if friction == 0:
                raise RobotFileError(f"{loc('friction_velocity')}: given without a non-zero friction")
            v_c = number("friction_velocity", f"vc_{i}", speed,
                         "velocity scale v_c of the smooth Coulomb friction F_c tanh(qd / v_c)")
            value = numeric(v_c, self.values)
            if v_c == 0 or (value is not None and not value > 0):
                raise RobotFileError(f"{loc('friction_velocity')}: must be > 0, got {table['friction_velocity']!r}")
            return friction, v_c
        if friction == 0:
            return friction, sp.Integer(0)
        if "v_coulomb" not in self.auto:
            self._auto_parameter(sp.Float(0.01), "v_coulomb", "", "velocity scale of the smooth Coulomb friction "
                                 "F_c tanh(qd / v_c) (rad/s or m/s)", loc("friction"))
        return friction, self.auto["v_coulomb"].symbol

    def _limits(self, table, prismatic, loc):
        """``limits = [lower, upper]`` (rad or m, numbers): the joint's range -- the validity range of q, or
        its end stops with ``limits="stops"``."""
        if "limits" not in table:
            return None
        raw = table["limits"]
        where_ = loc("limits")
        if not isinstance(raw, list) or len(raw) != 2 or any(isinstance(v, (list, dict, bool)) for v in raw):
            raise RobotFileError(f"{where_}: expected [lower, upper] ({'m' if prismatic else 'rad'}), got {raw!r}")
        values = []
        for k, v in enumerate(raw):
            expr = self._parse(v, f"{where_}[{k}]")
            if expr.free_symbols:
                raise RobotFileError(f"{where_}[{k}]: must be a number, got {v!r}")
            values.append(self._double(expr, v, f"{where_}[{k}]"))
        if not values[0] < values[1]:
            raise RobotFileError(f"{where_}: lower {values[0]!r} must be below upper {values[1]!r}")
        return Limits(values[0], values[1])

    def _inertia(self, table, i, label, mass, com, loc) -> sp.Matrix:
        has_tensor, has_gyration = "inertia" in table, "gyration_sq" in table
        if has_tensor == has_gyration:
            raise RobotFileError(f"{loc('inertia')}: give exactly one of 'inertia' and 'gyration_sq'")
        about = self._choice(table.get("inertia_about", "com"), ("com", "origin"), None, loc("inertia_about"))
        point = "its centre of mass" if about == "com" else f"the frame-{i} origin"
        if has_tensor:
            J = self._tensor(table["inertia"], loc("inertia"), i, label, point)
        else:
            k2 = self._vector(table["gyration_sq"], loc("gyration_sq"), f"k2_{i}_" + "{0}{0}", "m2",
                              "squared radius of gyration about the {} axis through " + f"{point}, of {label}",
                              nonnegative="squared radius of gyration")
            J = mass * sp.diag(*k2)
        if about == "origin":
            r = sp.Matrix(com)
            J = J - mass * ((r.T * r)[0, 0] * sp.eye(3) - r * r.T)
        return J

    def _tensor(self, value, loc, i, label, point) -> sp.Matrix:
        if isinstance(value, list) and len(value) == 3 and not any(isinstance(v, list) for v in value):
            rows = [[self._parse(value[r], f"{loc}[{r}]") if r == c else sp.Integer(0) for c in range(3)]
                    for r in range(3)]
        elif isinstance(value, list) and len(value) == 3 and all(isinstance(v, list) and len(v) == 3 for v in value):
            rows = [[self._parse(value[r][c], f"{loc}[{r}][{c}]") for c in range(3)] for r in range(3)]
        else:
            raise RobotFileError(
                f"{loc}: expected a 3x3 matrix [[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]] "
                f"or the diagonal [Ixx, Iyy, Izz], got {value!r}"
            )
        check_symmetric(rows, loc, self.values)
        for r in range(3):
            for c in range(3):
                self._check_unit(rows[r][c], "kg.m2", f"{loc}[{r}][{c}]")
        for r in range(3):
            check_nonnegative(rows[r][r], self.values, f"{loc}[{r}][{r}]", "moment of inertia", "kg m^2")
        J = sp.zeros(3, 3)
        for r, c, axes in PAIRS:
            what = (f"inertia tensor entry {axes} (products negated) about {point}, frame-{i} axes, of {label}")
            J[r, c] = J[c, r] = self._auto_parameter(rows[r][c], f"I_{i}_{axes}", "kg.m2", what, loc)
        return J

    def _check_body(self, mass, inertia_com, allow: bool, loc: str, label: str) -> None:
        m = numeric(mass, self.values)
        I = numeric_matrix(inertia_com.tolist(), self.values)
        if m is None or I is None:
            return  # symbolic: nothing to check until values are given
        problems = inertia_problems(m, I)
        if not problems:
            return
        text = "; ".join(problems)
        if allow:
            warnings.warn(
                f"{loc}: not a realisable rigid body: {text} "
                "(accepted because the file sets allow_unrealisable_inertia = true)",
                UnrealisableInertiaWarning,
                stacklevel=5,
            )
            return
        raise RobotFileError(
            f"{loc}: not a realisable rigid body: {text}. "
            "Fix the data, or set allow_unrealisable_inertia = true on the link or in [robot] "
            "if you really mean it"
        )

    def _check_well_posed(self, links, payload) -> None:
        """Refuse a chain whose mass matrix is singular (a joint that moves no
        mass, no inertia about its axis and no rotor): forward dynamics would
        fail only in the FMU, at initialisation.  Checked when every value is known."""
        def num(e):
            return numeric(e, self.values)

        data = []
        for link in links:
            I = numeric_matrix([list(r) for r in link.inertia_com], self.values)
            vals = [num(e) for e in (link.a, link.alpha, link.d, link.theta, link.mass, link.rotor_inertia)]
            com = [num(e) for e in link.com]
            if I is None or None in vals or None in com:
                return
            a, alpha, d, theta, m, rotor = vals
            data.append(dict(prismatic=link.joint == PRISMATIC, a=a, alpha=alpha, d=d, theta=theta,
                             mass=m, com=com, inertia=I, rotor=rotor))
        pl = None
        if payload is not None:
            pm, pc = num(payload.mass), [num(e) for e in payload.com]
            if pm is None or None in pc:
                return
            pl = (pm, pc)
        found = singular_joint(data, self.convention == MODIFIED, pl)
        if found is None:
            return
        j, q = found
        if j < 0:
            raise RobotFileError(
                f"{self.file}: the mass matrix overflows double precision (at q = "
                f"[{', '.join(f'{v:.3g}' for v in q)}]): masses, lengths or inertias are too large")
        link = links[j]
        raise RobotFileError(
            f"{where(self.file, j + 1, link.name)}: the mass matrix is singular (at q = "
            f"[{', '.join(f'{v:.3g}' for v in q)}]): joint {j + 1} moves no mass, no inertia about its axis "
            "and no rotor inertia, so its acceleration is undefined. Give the links it carries a mass "
            "or inertia, or the joint a rotor_inertia")

    def _payload(self, table) -> Payload:
        loc = where(self.file, field="[payload]")
        table = self._table(table, "[payload]")
        self._keys(table, PAYLOAD_KEYS, loc)
        mass = self._parse(table["mass"], loc + ": mass")
        self._check_unit(mass, "kg", loc + ": mass")
        check_nonnegative(mass, self.values, loc + ": mass", "payload mass", "kg")
        mass = self._auto_parameter(mass, "m_L", "kg", "payload mass (point mass on the last link)", loc + ": mass")
        com = self._vector(table["com"], loc + ": com", "rc_L_{}", "m", "payload position, {} in the last link frame")
        return Payload(mass=mass, com=com)

    # -------------------------------------------------------------- helpers
    def _parse(self, value, loc: str) -> sp.Expr:
        try:
            expr = quantity(value)
        except ExpressionError as exc:
            raise RobotFileError(f"{loc}: {exc}") from None
        self.user_names |= {s.name for s in expr.free_symbols}
        if expr.free_symbols and self.values:
            # with the declared values substituted, the number must still be a double
            e = sp.sympify(expr.xreplace(self.values))  # a bare symbol becomes a Python float
            if not e.free_symbols:
                self._double(e, value, loc, " with the [parameters] values")
        return expr

    def _double(self, expr, text, loc: str, how: str = "") -> float:
        try:
            return check_double(expr, repr(text) + how)
        except ExpressionError as exc:
            raise RobotFileError(f"{loc}: {exc}") from None

    def _unit(self, unit: str, loc: str) -> None:
        from ..fmi.units import base_units

        try:
            base_units(unit)
        except ValueError as exc:
            raise RobotFileError(f"{loc}: {exc}") from None

    def _vector(self, value, loc, auto, unit, what, nonnegative=None) -> tuple:
        if not isinstance(value, list) or len(value) != 3 or any(isinstance(v, (list, dict)) for v in value):
            raise RobotFileError(f"{loc}: expected a list of 3 numbers or expressions, got {value!r}")
        out = []
        for k, v in enumerate(value):
            axis = AXES[k]
            expr = self._parse(v, f"{loc}[{k}]")
            self._check_unit(expr, unit, f"{loc}[{k}]")
            if nonnegative:
                check_nonnegative(expr, self.values, f"{loc}[{k}]", nonnegative, unit)
            out.append(self._auto_parameter(expr, auto.format(axis), unit, what.format(axis), f"{loc}[{k}]"))
        return tuple(out)

    def _check_unit(self, expr, unit: str, loc: str) -> None:
        """A field written with declared [parameters] must come out in the field's unit (a mass
        declared unit = "m" used as a mass is refused)."""
        declared = {p.symbol: p.unit for p in self.declared.values() if p.unit}
        if declared and sp.sympify(expr).free_symbols & set(declared):
            problem = unit_problem(expr, unit, declared)
            if problem:
                raise RobotFileError(f"{loc}: {problem}")

    def _keys(self, table: dict, spec: dict, loc: str) -> None:
        unknown = [k for k in table if k not in spec]
        if unknown:
            k = unknown[0]
            close = difflib.get_close_matches(k, list(spec), n=1, cutoff=0.6)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            allowed = ", ".join(spec)
            raise RobotFileError(f"{loc}: unknown field {k!r}{hint}; allowed: {allowed}")
        missing = [k for k, required in spec.items() if required and k not in table]
        if missing:
            raise RobotFileError(f"{loc}: missing required field(s): {', '.join(missing)}")

    def _table(self, value, name: str) -> dict:
        if not isinstance(value, dict):
            raise RobotFileError(f"{self.file}: {name}: expected a table, got {type(value).__name__}")
        return value

    def _string(self, value, field, loc=None) -> str:
        if not isinstance(value, str):
            raise RobotFileError(f"{loc or where(self.file, field=field)}: expected a string, got {value!r}")
        return value

    def _bool(self, value, field, loc=None) -> bool:
        if not isinstance(value, bool):
            raise RobotFileError(f"{loc or where(self.file, field=field)}: expected true or false, got {value!r}")
        return value

    def _choice(self, value, allowed, field, loc=None) -> str:
        loc = loc or where(self.file, field=field)
        if value not in allowed:
            close = difflib.get_close_matches(str(value), allowed, n=1, cutoff=0.5)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise RobotFileError(f"{loc}: unknown value {value!r}{hint}; allowed: {', '.join(allowed)}")
        return value

