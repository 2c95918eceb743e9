"""Read a URDF file into a :class:`~fmugen.robot.description.Robot` (the joint model).

URDF is untrusted input: it is parsed as data and nothing in it is run.

* **The XML parser.**  ``defusedxml`` (the Python security team's hardened
  front end to the standard library's expat parser) with ``forbid_dtd``,
  ``forbid_entities`` and ``forbid_external``: a file with a DOCTYPE, an
  entity declaration or an external reference is refused before anything is
  expanded, so "billion laughs", quadratic blow-up, external entities and DTD
  retrieval cannot happen.  It was chosen over the bare standard library
  (whose expat expands internal entities) and over lxml (hardened only when
  every one of ``resolve_entities``, ``no_network``, ``huge_tree``, ``load_dtd``
  is set right, and a large C dependency for one file format); a URDF needs
  none of DTDs or entities.  Before parsing, the file is limited to
  :data:`MAX_BYTES`; after parsing, to :data:`MAX_ELEMENTS` elements and
  :data:`MAX_DEPTH` levels, and to :data:`MAX_JOINTS` joints.
* **xacro** files (macros, ``${...}`` expressions, ``<xacro:include>``) are
  refused with a hint to expand them first (``xacro robot.urdf.xacro >
  robot.urdf``); a mere ``xmlns:xacro`` declaration is fine.
* **Names**: link and joint names must be at most 128 characters of
  ``[A-Za-z0-9_.-/]``; they appear in descriptions and frame names.
  Parameter names are derived from them with every other character written
  ``_`` (``m_upper_arm_link``), made unique.

What is read
------------
* ``<link>``: ``<inertial>`` -- ``<origin xyz rpy>`` (the centre of mass and
  the orientation of the inertia axes), ``<mass value>``, ``<inertia ixx ixy
  ixz iyy iyz izz>`` (about the centre of mass, in the inertial frame; URDF's
  ixy is the tensor entry, i.e. the negated product of inertia).  A link
  without ``<inertial>`` has no mass.  ``<visual>``, ``<collision>``,
  meshes and ``package://`` paths are ignored (dynamics only).
* ``<joint type>``: ``revolute``, ``continuous`` (revolute without position
  limits), ``prismatic`` and ``fixed``; ``<parent link>``, ``<child link>``,
  ``<origin xyz rpy>`` (R = Rz(yaw) Ry(pitch) Rx(roll)), ``<axis xyz>``
  (default 1 0 0, normalised), ``<limit lower upper effort velocity>``
  (validity ranges: q in [lower, upper], |tau| <= effort), ``<dynamics
  damping friction>`` (viscous damping b qd; Coulomb friction, see below),
  ``<mimic joint multiplier offset>`` (read as an independent joint, with a
  warning naming it, as Pinocchio's parser does; ``load_urdf(path,
  mimic="tied")`` ties it to its leader instead: q = multiplier q_leader +
  offset, and the state-space model keeps only the leader).
* ``fixed`` joints are merged: the child link's mass, centre of mass and
  inertia are added exactly to the moving body it is welded to (or dropped
  when welded to the fixed base), and the child link stays a named frame
  (:class:`~fmugen.robot.description.Frame`) for kinematics.
* ``floating`` and ``planar`` joints, a joint of any other type, a link with
  two parents, several root links and cycles are refused with one line
  naming the joint or link.

Coulomb friction: a joint's ``friction`` F_c enters the generalized force as
the smooth term ``F_c tanh(qd / v_c)`` (v_c: the parameter ``v_coulomb``,
default 0.01 rad/s or m/s), documented in ``robots/README.md``.

Every non-zero number of masses, centres of mass, inertias, joint origins
(``xyz``), damping and friction becomes a named parameter (``m_<link>``,
``rc_<link>_x``, ``I_<link>_xy``, ``p_<joint>_x``, ``b_<joint>``,
``fc_<joint>``), so ``--set`` changes any of them in the FMU; the
orientations (``rpy``) and axes stay constants (structure, like DH angles).
Gravity is ``g_z = -9.81`` m/s^2 along the base z axis, as in Pinocchio.
"""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import sympy as sp

from ..errors import MAX_IDENTIFIER_LENGTH, InputFileError, read_text_file
from .checks import RobotFileError, UnrealisableInertiaWarning, inertia_problems
from .description import JOINTS, PRISMATIC, REVOLUTE, Body, Frame, Limits, Parameter, Robot
from .expressions import symbol_name_problem
from ..values import parse_xs_double, parse_xs_double_list

__all__ = ["load_urdf", "robot_from_urdf", "MAX_BYTES", "MAX_ELEMENTS", "MAX_DEPTH", "MAX_JOINTS",
           "MimicJointWarning"]

MAX_BYTES = 16 * 2**20
MAX_ELEMENTS = 200_000
MAX_DEPTH = 32
MAX_JOINTS = 2000
NAME = re.compile(r"[A-Za-z0-9_./-]{1,128}\Z")
MOVING = {"revolute": REVOLUTE, "continuous": REVOLUTE, "prismatic": PRISMATIC}
REFUSED = {"floating": "a floating joint (a free-flying base)", "planar": "a planar joint"}
_Z, _ONE = sp.Integer(0), sp.Integer(1)
PAIRS = ((0, 0, "xx"), (1, 1, "yy"), (2, 2, "zz"), (0, 1, "xy"), (0, 2, "xz"), (1, 2, "yz"))


class MimicJointWarning(UserWarning):
    """The URDF has mimic joints; fmugen reads them as independent joints."""


def load_urdf(path, mimic: str = "independent", armature: dict | None = None) -> Robot:
    """Read, check and convert the URDF file at ``path``.

    ``mimic``: "independent" (every mimic joint is a joint of its own, with a
    :class:`MimicJointWarning`) or "tied" (``Body.mimic``: the state-space
    model keeps only the leader, q = multiplier q_leader + offset).
    """
    path = Path(path)
    if path.name.endswith(".xacro"):
        raise RobotFileError(f"{path}: a xacro file; expand it to plain URDF first "
                             f"(xacro {path.name} > {path.name[:-6] or 'robot'}.urdf), then load that")
    try:
        size = path.stat().st_size
    except OSError:
        size = 0  # read_text_file names the problem
    if size > MAX_BYTES:
        raise RobotFileError(f"{path}: {size} bytes; a URDF file is read up to {MAX_BYTES} bytes")
    try:
        text = read_text_file(path, "URDF file")
    except InputFileError as exc:
        raise RobotFileError(str(exc)) from None
    return robot_from_urdf(text, source=str(path), stem=path.stem, mimic=mimic, armature=armature)


def robot_from_urdf(text: str, source: str = "<string>", stem: str = "robot", mimic: str = "independent",
                    armature: dict | None = None) -> Robot:
    """Like :func:`load_urdf` for the text of a URDF file; ``source`` names it in messages."""
    if mimic not in ("independent", "tied"):
        raise ValueError(f"mimic must be 'independent' or 'tied', not {mimic!r}")
    if len(text.encode("utf-8", "surrogatepass")) > MAX_BYTES:
        raise RobotFileError(f"{source}: more than {MAX_BYTES} bytes; a URDF file is read up to that size")
    root = _parse(text, source)
    return _Reader(source, mimic, armature).robot(root, stem)


# ------------------------------------------------------------------ parsing
def _parse(text: str, source: str):
    import defusedxml
    import defusedxml.ElementTree as DET
    from xml.etree.ElementTree import ParseError

    try:
        root = DET.fromstring(text, forbid_dtd=True, forbid_entities=True, forbid_external=True)
    except defusedxml.DTDForbidden:
        raise RobotFileError(f"{source}: has a DOCTYPE declaration; DTDs are not read in URDF files "
                             "(untrusted input: remove the <!DOCTYPE ...>)") from None
    except defusedxml.EntitiesForbidden:
        raise RobotFileError(f"{source}: declares XML entities; entities are not expanded in URDF files "
                             "(untrusted input)") from None
    except defusedxml.DefusedXmlException as exc:
        raise RobotFileError(f"{source}: refused XML construct: {exc}") from None
    except ParseError as exc:
        line, col = getattr(exc, "position", (0, 0))
        hint = ""
        if "unbound prefix" in str(exc) and "xacro:" in text:
            hint = "; this looks like an unexpanded xacro file: run xacro on it first"
        raise RobotFileError(f"{source}: line {line}, column {col}: XML syntax error: "
                             f"{str(exc).split(':')[0]}{hint}") from None
    # element count and depth, iteratively (no recursion on untrusted nesting)
    count, stack = 0, [(root, 1)]
    while stack:
        el, depth = stack.pop()
        count += 1
        if count > MAX_ELEMENTS:
            raise RobotFileError(f"{source}: more than {MAX_ELEMENTS} XML elements; refused")
        if depth > MAX_DEPTH:
            raise RobotFileError(f"{source}: XML nested deeper than {MAX_DEPTH} levels; refused")
        tag = el.tag if isinstance(el.tag, str) else ""
        if "xacro" in tag.lower() or any("${" in v or "$(" in v for v in el.attrib.values()):
            raise RobotFileError(f"{source}: contains xacro macros ({_short(tag)}); expand the file first "
                                 "(xacro robot.urdf.xacro > robot.urdf) and load the result")
        stack.extend((c, depth + 1) for c in el)
    return root


def _short(text, n=60) -> str:
    text = str(text)
    return repr(text if len(text) <= n else text[:n] + "...")


# ------------------------------------------------------------------ geometry
def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the URDF convention (fixed axes x, y, z)."""
    r, p, y = rpy
    cr, sr, cp, spi, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, spi], [0, 1, 0], [-spi, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _exact(x: float) -> sp.Expr:
    """A float as sympy: exact 0, 1, -1 (structure the algebra can fold), else a Float."""
    if x == 0.0:
        return _Z
    if x == 1.0:
        return _ONE
    if x == -1.0:
        return -_ONE
    return sp.Float(x)


def _smatrix(R: np.ndarray) -> sp.Matrix:
    return sp.Matrix(3, 3, [_exact(float(v)) for v in R.ravel()])


class _Reader:
    def __init__(self, source: str, mimic: str = "independent", armature: dict | None = None):
        self.file = source
        self.mimic = mimic
        self.armature = dict(armature or {})
        self.params: dict = {}  # name -> Parameter
        self.taken: set = set()

    # -------------------------------------------------------------- helpers
    def _err(self, what: str, msg: str):
        return RobotFileError(f"{self.file}: {what}: {msg}")

    def _name(self, el, what: str) -> str:
        name = el.get("name")
        if name is None:
            raise self._err(what, "missing attribute 'name'")
        if not NAME.match(name):
            raise self._err(f"{what} {_short(name)}", "name must be 1-128 characters of letters, digits "
                                                         "and _ . - /")
        return name

    def _floats(self, el, attr: str, n: int, what: str, default=None) -> list:
        """The ``n`` numbers of attribute ``attr``: URDF's attributes are XML Schema values -- one
        xs:double, or a list of them separated by XML white space (``xyz="0 0 1"``).  ``float()``
        would also take ``1_5``, Arabic-Indic digits, ``nan``, ``infinity``; those are refused."""
        raw = el.get(attr) if el is not None else None
        if raw is None:
            if default is None:
                raise self._err(what, f"missing attribute {attr!r}")
            return list(default)
        where = f"{self.file}: {what}: {attr}"
        try:
            if n == 1:
                return [parse_xs_double(raw, where)]
            items = raw.strip(" \t\n\r")
            count = len(re.split(r"[ \t\n\r]+", items)) if items else 0
            if count != n:
                raise self._err(what, f"{attr}={_short(raw)}: expected {n} numbers separated by spaces, "
                                      f"found {count}")
            return parse_xs_double_list(raw, where, n)
        except RobotFileError:
            raise
        except InputFileError as exc:
            raise RobotFileError(str(exc)) from None

    def _float(self, el, attr, what, default=None):
        return self._floats(el, attr, 1, what, None if default is None else [default])[0]

    def _ident(self, text: str) -> str:
        s = re.sub(r"[^A-Za-z0-9_]", "_", text)
        return s[:40]

    def _param(self, stem: str, owner: str, value: float, unit: str, description: str) -> sp.Expr:
        """A parameter named ``stem_owner`` for a non-zero ``value``; exact 0 stays a structural zero."""
        if value == 0.0:
            return _Z
        base = stem.format(self._ident(owner)) if "{}" in stem else stem
        name, k = base, 2
        while name in self.taken or symbol_name_problem(name):
            name, k = f"{base}_{k}", k + 1
        self.taken.add(name)
        symbol = sp.Symbol(name, real=True)
        self.params[name] = Parameter(name, symbol, float(value), unit, description)
        return symbol

    # -------------------------------------------------------------- the file
    def robot(self, root, stem: str) -> Robot:
        if root.tag != "robot":
            raise self._err(f"<{_short(root.tag, 30)[1:-1]}>", "the root element of a URDF file must be <robot>")
        raw_name = root.get("name") or stem
        name = re.sub(r"[^A-Za-z0-9_]", "_", raw_name)[:MAX_IDENTIFIER_LENGTH]
        if not name or not name[0].isalpha():
            name = ("urdf_" + name)[:MAX_IDENTIFIER_LENGTH]

        links, order = {}, []
        for el in root.findall("link"):
            n = self._name(el, "<link>")
            if n in links:
                raise self._err(f"link {n!r}", "defined twice")
            links[n] = el
            order.append(n)
        if not links:
            raise self._err("<robot>", "no <link> elements")
        joints = []
        seen = {}
        for el in root.findall("joint"):
            j = self._joint(el, links)
            if j["name"] in seen:
                raise self._err(f"joint {j['name']!r}", "defined twice")
            seen[j["name"]] = j
            joints.append(j)
        if len(joints) > MAX_JOINTS:
            raise self._err("<robot>", f"{len(joints)} joints; at most {MAX_JOINTS} are read")

        # the graph: one parent per link, one root, no cycle
        parent_joint = {}
        for j in joints:
            c = j["child"]
            if c in parent_joint:
                raise self._err(f"joint {j['name']!r}", f"link {c!r} already has a parent (joint "
                                                         f"{parent_joint[c]['name']!r}); a URDF must be a tree")
            parent_joint[c] = j
        roots = [n for n in order if n not in parent_joint]
        if len(roots) != 1:
            if not roots:
                j = joints[0]
                raise self._err(f"joint {j['name']!r}", "the links form a cycle: no root link")
            raise self._err("<robot>", f"{len(roots)} root links ({', '.join(repr(r) for r in roots[:5])}); "
                                       "a URDF must be one tree (join them by joints)")
        children = {n: [] for n in order}
        for j in joints:
            children[j["parent"]].append(j)
        reached = set()
        stack = [roots[0]]
        while stack:
            n = stack.pop()
            reached.add(n)
            stack.extend(j["child"] for j in children[n])
        if len(reached) != len(links):
            cyc = next(j for j in joints if j["child"] not in reached)
            raise self._err(f"joint {cyc['name']!r}", "on a cycle of links not connected to the root "
                                                      f"link {roots[0]!r}")
        for j in joints:
            if j["type"] in REFUSED:
                raise self._err(f"joint {j['name']!r}", f"type {j['type']!r}: {REFUSED[j['type']]} is not "
                                "supported (fixed-base robots with revolute, continuous, prismatic and fixed "
                                "joints only)")
        self._joint_mimic = {j["name"]: j["mimic"] for j in joints}
        mimics = [j["name"] for j in joints if j["mimic"]]
        if mimics and self.mimic == "independent":
            warnings.warn(f"{self.file}: mimic joints read as independent joints (as Pinocchio's parser "
                          f"does): {', '.join(mimics)}", MimicJointWarning, stacklevel=4)

        # bodies in depth-first preorder (children in document order), fixed joints merged:
        # a stack entry is (link, body it is welded to, its pose in that body's frame, moving joint or None)
        bodies, frames, parts = [], [], []
        unrealisable = []
        E3, O3 = sp.eye(3), sp.zeros(3, 1)
        frames.append(Frame(roots[0], -1, _rows(E3), (_Z, _Z, _Z)))
        stack = [(roots[0], -1, E3, O3, None)]
        while stack:
            link, body, R_lb, p_lb, joint = stack.pop()
            if joint is not None:  # a moving joint: link is the body frame of a new body
                bodies.append(dict(j=joint, parent=body, R=R_lb, p=p_lb, link=link))
                parts.append([])
                body, R_lb, p_lb = len(bodies) - 1, E3, O3
            inertial = self._inertial(links[link], link, unrealisable)
            if inertial is not None and body >= 0:
                m, c, I = inertial
                parts[body].append((m, R_lb * c + p_lb, R_lb * I * R_lb.T))
            for j in reversed(children[link]):
                R_j = R_lb * j["R"]
                p_j = R_lb * j["p"] + p_lb
                if j["type"] == "fixed":
                    frames.append(Frame(j["child"], body, _rows(R_j), tuple(p_j)))
                    stack.append((j["child"], body, R_j, p_j, None))
                else:
                    stack.append((j["child"], body, R_j, p_j, j))
        if not bodies:
            raise self._err("<robot>", "no revolute, continuous or prismatic joint: nothing moves")
        if unrealisable:
            warnings.warn(f"{self.file}: inertia not realisable as a rigid body (kept as given): "
                          + "; ".join(unrealisable[:5]) + (" ..." if len(unrealisable) > 5 else ""),
                          UnrealisableInertiaWarning, stacklevel=4)
        gravity = (_Z, _Z, self._param("g_z", "", -9.81, "m/s2", "gravitational acceleration, z component in "
                                                            "the base frame"))
        v_c = None
        out = []
        for k, b in enumerate(bodies):
            j = b["j"]
            mass, com, inertia = _combine(parts[k])
            friction = j["friction"]
            if friction != 0 and v_c is None:
                v_c = self._param("v_coulomb", "", 0.01, "", "velocity scale of the smooth Coulomb friction "
                                  "F_c tanh(qd / v_c) (rad/s or m/s)")
            R = b["R"]
            out.append(Body(
                name=b["link"], joint=MOVING[j["type"]], parent=b["parent"],
                rotation=tuple(tuple(R.row(r)) for r in range(3)), translation=tuple(b["p"]),
                axis=j["axis"], mass=mass, com=com, inertia_com=inertia,
                damping=j["damping"], friction=friction, friction_velocity=v_c if friction != 0 else _Z,
                joint_name=j["name"], limits=j["limits"]))
        out = self._armature(out)
        used = set()
        for b in out:
            for e in (b.mass, b.rotor_inertia, b.damping, b.friction, b.friction_velocity, *b.com, *b.translation,
                      *(x for row in b.inertia_com for x in row)):
                used |= sp.sympify(e).free_symbols
        for f in frames:
            for e in f.translation:
                used |= sp.sympify(e).free_symbols
        used |= gravity[2].free_symbols
        if self.mimic == "tied":
            out = self._tie(out)
        params = tuple(p for p in self.params.values() if p.symbol in used)
        self._check_moves_something(out, {p.symbol: p.value for p in params})
        return Robot(
            name=name, convention=JOINTS, links=(), gravity=gravity, parameters=params,
            description=f"{name}: read from a URDF file",  # the file's own text never reaches C or XML
            source=self.file, bodies=tuple(out), frames=tuple(frames), end_frame=out[-1].name)

    def _armature(self, bodies) -> list:
        """Rotor (armature) inertia of the joints named in ``armature`` (URDF has no field for it).

        Added to M_ii as ``model.armature`` is in Pinocchio (and ``rotor_inertia``
        in fmugen's TOML robots); a named FMU parameter ``Ia_<joint>`` (kg.m2, or
        kg on a prismatic joint) that ``--set`` changes.  It is what makes a joint
        that moves no mass (Romeo's hands: links without <inertial>) buildable.
        """
        moving = {b.joint_name: i for i, b in enumerate(bodies)}
        out = list(bodies)
        for joint, value in self.armature.items():
            what = f"armature {{ {_short(str(joint))} = ... }}"
            if joint not in moving:
                raise self._err(what, f"no moving joint of that name; joints: {', '.join(list(moving)[:8])}"
                                + (" ..." if len(moving) > 8 else ""))
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                    or value < 0:
                raise self._err(what, f"must be a finite number >= 0, got {value!r}")
            i = moving[joint]
            rev = out[i].joint == REVOLUTE
            ia = self._param("Ia_{}", joint, float(value), "kg.m2" if rev else "kg",
                             f"rotor (armature) inertia of joint {joint}, added to M_ii (not in the URDF: "
                             f"given as armature)")
            out[i] = replace(out[i], rotor_inertia=ia)
        return out

    def _tie(self, bodies) -> list:
        """Body.mimic = (leader index, multiplier, offset) for every mimic joint (leaders must move freely)."""
        index = {b.joint_name: i for i, b in enumerate(bodies)}
        out = []
        for b in bodies:
            spec = self._joint_mimic.get(b.joint_name)
            if spec is None:
                out.append(b)
                continue
            leader, mult, off = spec
            what = f"joint {b.joint_name!r}: <mimic joint={_short(leader)}>"
            if leader not in index:
                raise self._err(what, "no such moving joint")
            if self._joint_mimic.get(leader) is not None:
                raise self._err(what, "its leader is itself a mimic joint; tie each to the first leader")
            out.append(replace(b, mimic=(index[leader], sp.Float(mult) if mult != 1 else _ONE,
                                         _exact(off))))
        return out

    def _check_moves_something(self, bodies, values) -> None:
        """Refuse a joint whose subtree has no mass and no inertia about its axis (M_ii = 0: M singular).

        The diagonal of M by composite rigid bodies at q = 0, numerically: a
        joint that moves only massless links (a URDF without <inertial> on
        them) would make the FMU's forward dynamics fail at its first call.
        """
        n = len(bodies)
        num = lambda e: float(sp.sympify(e).xreplace(values))  # noqa: E731
        comp = [None] * n  # (m, first moment h, inertia about the body origin) of the subtree, body frame
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused below, by name
            self._composite(bodies, num, comp)
        self._check_diagonal(bodies, num, comp)

    def _composite(self, bodies, num, comp) -> None:
        n = len(bodies)
        for i in range(n - 1, -1, -1):
            b = bodies[i]
            m = num(b.mass)
            c = np.array([num(x) for x in b.com])
            Ic = np.array([[num(x) for x in row] for row in b.inertia_com])
            h = m * c
            I = Ic + m * (c @ c * np.eye(3) - np.outer(c, c))
            for k in range(i + 1, n):
                if bodies[k].parent != i:
                    continue
                mk, hk, Ik = comp[k]
                R = np.array([[num(x) for x in row] for row in bodies[k].rotation])
                p = np.array([num(x) for x in bodies[k].translation])
                hr = R @ hk
                m, h = m + mk, h + mk * p + hr
                I = I + R @ Ik @ R.T + mk * (p @ p * np.eye(3) - np.outer(p, p)) \
                    + 2 * (p @ hr) * np.eye(3) - np.outer(p, hr) - np.outer(hr, p)
            comp[i] = (m, h, I)

    def _check_diagonal(self, bodies, num, comp) -> None:
        scale = max([abs(c[0]) for c in comp] + [np.abs(c[2]).max() for c in comp] + [1e-300])
        if not all(np.isfinite(c[0]) and np.all(np.isfinite(c[1])) and np.all(np.isfinite(c[2])) for c in comp):
            raise RobotFileError(f"{self.file}: the mass matrix overflows double precision (at q = 0): masses, "
                                 f"lengths or inertias are too large")
        for i, b in enumerate(bodies):
            k = np.array([num(x) for x in b.axis])
            m, h, I = comp[i]
            with np.errstate(over="ignore", invalid="ignore"):
                mii = (k @ I @ k if b.joint == REVOLUTE else m) + num(b.rotor_inertia)
            if not math.isfinite(mii):
                raise RobotFileError(f"{self.file}: the mass matrix overflows double precision (at q = 0): "
                                     f"masses, lengths or inertias are too large")
            if mii <= 1e-12 * scale:
                unit = "kg.m2" if b.joint == REVOLUTE else "kg"
                raise self._err(f"joint {b.joint_name!r}", "moves no mass and no inertia about its axis (the links "
                                "it carries have no <inertial>, or no mass off its axis and no inertia about it): "
                                "the mass matrix is singular; give them inertials, "
                                "make the joint fixed, or give it a rotor (armature) inertia Ia_<joint> "
                                f"[{unit}]: armature = {{ {b.joint_name} = 1e-3 }} in a scene's robot instance, "
                                f"fmugen.load_robot(..., armature={{{b.joint_name!r}: 1e-3}}) "
                                "(Pinocchio: model.armature)")

    def _joint(self, el, links) -> dict:
        name = self._name(el, "<joint>")
        what = f"joint {name!r}"
        jtype = el.get("type")
        if jtype not in MOVING and jtype != "fixed" and jtype not in REFUSED:
            raise self._err(what, f"unknown type {_short(jtype)}; allowed: revolute, continuous, prismatic, fixed")
        ends = {}
        for tag in ("parent", "child"):
            sub = el.find(tag)
            if sub is None or sub.get("link") is None:
                raise self._err(what, f"missing <{tag} link=...>")
            if sub.get("link") not in links:
                raise self._err(what, f"<{tag} link={_short(sub.get('link'))}>: no such link")
            ends[tag] = sub.get("link")
        origin = el.find("origin")
        xyz = self._floats(origin, "xyz", 3, f"{what}: <origin>", [0, 0, 0])
        rpy = self._floats(origin, "rpy", 3, f"{what}: <origin>", [0, 0, 0])
        p = sp.Matrix([self._param(f"p_{{}}_{ax}", name, v, "m", f"origin of joint {name}, {ax} in the parent "
                                   "link frame") for v, ax in zip(xyz, "xyz")])
        axis = self._floats(el.find("axis"), "xyz", 3, f"{what}: <axis>", [1, 0, 0])
        norm = math.sqrt(sum(a * a for a in axis))
        if jtype in MOVING and norm < 1e-12:
            raise self._err(what, "<axis xyz>: zero vector")
        if all(a == int(a) for a in axis) and sorted(abs(a) for a in axis) == [0, 0, 1]:
            axis_s = tuple(sp.Integer(int(a)) for a in axis)
        else:
            axis_s = tuple(_exact(a / norm) for a in axis) if norm else (_ONE, _Z, _Z)
        lim = el.find("limit")
        limits = None
        if lim is not None and jtype in MOVING:
            def opt(attr):
                return self._float(lim, attr, f"{what}: <limit>") if lim.get(attr) is not None else None
            lower, upper = (opt("lower"), opt("upper")) if jtype != "continuous" else (None, None)
            if lower is not None and upper is not None and lower > upper:
                raise self._err(f"{what}: <limit>", f"lower {lower} > upper {upper}")
            if lower == upper == 0.0 and jtype != "continuous":
                lower = upper = None  # URDF's default "no limits given"
            effort, velocity = opt("effort"), opt("velocity")
            for v, attr in ((effort, "effort"), (velocity, "velocity")):
                if v is not None and v < 0:
                    raise self._err(f"{what}: <limit>", f"negative {attr} {v}")
            limits = Limits(lower, upper, effort or None, velocity or None)
        dyn = el.find("dynamics")
        damping = friction = _Z
        rev = MOVING.get(jtype) == REVOLUTE
        if dyn is not None and jtype in MOVING:
            b = self._float(dyn, "damping", f"{what}: <dynamics>", 0.0)
            fc = self._float(dyn, "friction", f"{what}: <dynamics>", 0.0)
            if b < 0 or fc < 0:
                raise self._err(f"{what}: <dynamics>", "negative damping or friction")
            damping = self._param("b_{}", name, b, "N.m.s/rad" if rev else "N.s/m",
                                  f"viscous damping of joint {name}")
            friction = self._param("fc_{}", name, fc, "N.m" if rev else "N",
                                   f"Coulomb friction of joint {name} (smooth: F_c tanh(qd / v_coulomb))")
        return dict(name=name, type=jtype, parent=ends["parent"], child=ends["child"], p=p,
                    R=_smatrix(rpy_matrix(rpy)), axis=axis_s, limits=limits, damping=damping,
                    friction=friction, mimic=self._mimic(el.find("mimic"), what))

    def _mimic(self, el, what):
        """(leader joint name, multiplier, offset) of a <mimic>, or None."""
        if el is None:
            return None
        leader = el.get("joint")
        if not leader:
            raise self._err(f"{what}: <mimic>", "missing attribute 'joint'")
        return (leader, self._float(el, "multiplier", f"{what}: <mimic>", 1.0),
                self._float(el, "offset", f"{what}: <mimic>", 0.0))

    def _inertial(self, el, link: str, unrealisable: list):
        """(mass, com, inertia about the COM in link axes) as sympy, or None without <inertial>."""
        inl = el.find("inertial")
        if inl is None:
            return None
        what = f"link {link!r}: <inertial>"
        mass_el = inl.find("mass")
        mass = self._float(mass_el, "value", what + ": <mass>") if mass_el is not None else 0.0
        if mass < 0:
            raise self._err(what + ": <mass>", f"negative mass {mass}")
        origin = inl.find("origin")
        xyz = self._floats(origin, "xyz", 3, what + ": <origin>", [0, 0, 0])
        rpy = self._floats(origin, "rpy", 3, what + ": <origin>", [0, 0, 0])
        ie = inl.find("inertia")
        vals = {}
        for key in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"):
            vals[key] = self._float(ie, key, what + ": <inertia>", 0.0) if ie is not None else 0.0
        In = np.array([[vals["ixx"], vals["ixy"], vals["ixz"]], [vals["ixy"], vals["iyy"], vals["iyz"]],
                       [vals["ixz"], vals["iyz"], vals["izz"]]])
        if mass == 0.0 and not In.any():
            return None
        problems = inertia_problems(mass, In)
        if problems:
            unrealisable.append(f"{link}: {problems[0]}")
        m = self._param("m_{}", link, mass, "kg", f"mass of link {link}")
        c = sp.Matrix([self._param(f"rc_{{}}_{ax}", link, v, "m", f"centre of mass of link {link}, {ax} in its "
                                   "frame") for v, ax in zip(xyz, "xyz")])
        I = sp.zeros(3, 3)
        for r, k, ax in PAIRS:
            I[r, k] = I[k, r] = self._param(f"I_{{}}_{ax}", link, float(In[r, k]), "kg.m2",
                                            f"inertia tensor entry {ax} of link {link} about its centre of mass, "
                                            "inertial-frame axes (products negated)")
        Ri = _smatrix(rpy_matrix(rpy))
        return m, c, Ri * I * Ri.T


def _rows(M: sp.Matrix) -> tuple:
    return tuple(tuple(M.row(r)) for r in range(3))


def _combine(parts) -> tuple:
    """(mass, com, inertia about the COM) of rigid parts given in one frame (exact, symbolic).

    A part without mass but with inertia (URDF allows it; Pinocchio adds it)
    adds its inertia and nothing else.
    """
    parts = [(sp.sympify(m), sp.Matrix(c), sp.Matrix(I)) for m, c, I in parts]
    massive = [(m, c, I) for m, c, I in parts if m != 0]
    extra = sp.zeros(3, 3)
    for m, _, I in parts:
        if m == 0:
            extra += I
    if not massive:
        return _Z, (_Z, _Z, _Z), _rows(extra)
    if len(massive) == 1:
        m, c, I = massive[0]
        return m, tuple(c), _rows(I + extra)
    M = sum(m for m, _, _ in massive)
    com = sum((m * c for m, c, _ in massive), sp.zeros(3, 1)) / M
    I_tot = extra
    for m, c, I in massive:
        d = c - com
        I_tot += I + m * ((d.T * d)[0, 0] * sp.eye(3) - d * d.T)
    return M, tuple(com), _rows(I_tot)
