"""Write any fmugen robot as a URDF file (``fmugen export-urdf robot.toml -o robot.urdf``).

So that a robot written in Denavit-Hartenberg parameters can be viewed in
other tools and checked with other libraries (Pinocchio, RBDL, ROS).  The
URDF says the same rigid bodies as :attr:`Robot.bodies` with every parameter
at its value (the file's, or ``values``):

* the base is a massless link ``base_link`` (a URDF robot's own root link
  keeps its name); body i is the link of its name,
  moved by the joint ``joint_name`` (a DH robot: ``joint1`` ... ``jointN``)
  whose ``<origin>`` is the body's placement -- with a DH offset (theta or d)
  folded in, as URDF has none -- and whose ``<axis>`` is the body's axis;
* revolute joints without limits are ``continuous``; limits, damping and
  friction are written when the robot has them;
* ``<inertial>``: the centre of mass as ``origin xyz`` (``rpy`` zero) and the
  full inertia tensor about it in the body frame; a payload is already merged
  into the last body;
* every named frame (``frame1`` ... ``frameN`` of a DH robot, URDF tool
  frames) becomes a massless link on a ``fixed`` joint ``<frame>_joint``.

URDF has no rotor (armature) inertia: a robot with ``rotor_inertia`` gets an
XML comment listing the values, and a warning -- Pinocchio users set
``model.armature`` from it.  Numbers are written with 17 significant digits
(``repr``), so a reader gets the same doubles.
"""
from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import sympy as sp

from .description import REVOLUTE, Robot

__all__ = ["robot_to_urdf", "rotation_rpy"]


def rotation_rpy(R) -> tuple:
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll) (the URDF convention)."""
    R = np.asarray(R, dtype=float)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.hypot(R[0, 0], R[1, 0]) > 1e-12:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    else:  # gimbal lock: only roll - yaw (or roll + yaw) is defined; take yaw = 0
        roll = math.atan2(-R[1, 2], R[1, 1])
        yaw = 0.0
    return roll, pitch, yaw


def _axis_angle(k, angle) -> np.ndarray:
    k = np.asarray(k, dtype=float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _num(x: float) -> str:
    x = float(x)
    return "0" if x == 0 else repr(x)


def _vec(v) -> str:
    return " ".join(_num(x) for x in v)


def robot_to_urdf(robot: Robot, values: dict | None = None) -> str:
    """The URDF text of ``robot`` with its parameters at their values (``values`` overrides by name)."""
    env = {}
    for p in robot.parameters:
        v = (values or {}).get(p.name, p.value)
        if v is None:
            raise ValueError(f"{robot.name}: parameter {p.name!r} has no value; give it "
                             f"(fmugen export-urdf ... --set {p.name}=VALUE)")
        env[p.symbol] = sp.Float(float(v))
    unknown = set(values or {}) - {p.name for p in robot.parameters}
    if unknown:
        raise KeyError(f"{robot.name}: unknown parameter(s) {sorted(unknown)}")

    def num(e) -> float:
        e = sp.sympify(e).xreplace(env)
        return float(e)

    def mat(rows) -> np.ndarray:
        return np.array([[num(x) for x in row] for row in rows])

    names = set()

    def unique(name: str) -> str:
        out, k = name, 2
        while out in names:
            out, k = f"{name}_{k}", k + 1
        names.add(out)
        return out

    root = ET.Element("robot", name=robot.name)
    # the source's file name only: a machine path would leak into a file that may be shipped
    source = Path(str(robot.source)).name if robot.source else "a Robot"
    root.append(ET.Comment(f" {robot.name}: written by fmugen export-urdf from {source} "))
    # a URDF robot's root link is a frame on the base (-1) at the identity: it names the base link
    root_frame = next((f for f in robot.frames if f.parent < 0 and all(num(x) == 0 for x in f.translation)
                       and np.array_equal(mat(f.rotation), np.eye(3))), None)
    base = unique(root_frame.name if root_frame is not None else "base_link")
    g = [num(x) for x in robot.gravity]
    root.append(ET.Comment(f" gravity (base frame, m/s2; URDF has no field for it): {_vec(g)} "))
    ET.SubElement(root, "link", name=base)
    link_of = {-1: base}
    for b in robot.bodies:
        link_of[len(link_of) - 1] = unique(b.name)
    rotors = []
    for i, b in enumerate(robot.bodies):
        link = ET.SubElement(root, "link", name=link_of[i])
        mass = num(b.mass)
        if mass != 0:
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "origin", xyz=_vec(num(c) for c in b.com), rpy="0 0 0")
            ET.SubElement(inertial, "mass", value=_num(mass))
            I = mat(b.inertia_com)
            ET.SubElement(inertial, "inertia", ixx=_num(I[0, 0]), ixy=_num(I[0, 1]), ixz=_num(I[0, 2]),
                          iyy=_num(I[1, 1]), iyz=_num(I[1, 2]), izz=_num(I[2, 2]))
        R, p, k = mat(b.rotation), np.array([num(x) for x in b.translation]), np.array([num(x) for x in b.axis])
        offset = num(b.offset)
        if offset:  # URDF has no joint offset: fold it into the placement
            if b.joint == REVOLUTE:
                R = R @ _axis_angle(k, offset)
            else:
                p = p + offset * (R @ k)
        lim = b.limits
        has_range = lim is not None and lim.lower is not None and lim.upper is not None
        jtype = ("revolute" if has_range else "continuous") if b.joint == REVOLUTE else "prismatic"
        joint = ET.SubElement(root, "joint", name=unique(b.joint_name or f"joint{i + 1}"), type=jtype)
        ET.SubElement(joint, "parent", link=link_of[b.parent])
        ET.SubElement(joint, "child", link=link_of[i])
        ET.SubElement(joint, "origin", xyz=_vec(p), rpy=_vec(rotation_rpy(R)))
        ET.SubElement(joint, "axis", xyz=_vec(k))
        if jtype != "continuous":
            lo = lim.lower if has_range else -1e3
            hi = lim.upper if has_range else 1e3
            effort = lim.effort if lim is not None and lim.effort else 1e6
            velocity = lim.velocity if lim is not None and lim.velocity else 1e3
            ET.SubElement(joint, "limit", lower=_num(lo), upper=_num(hi), effort=_num(effort),
                          velocity=_num(velocity))
        damping, friction = num(b.damping), num(b.friction)
        if damping or friction:
            ET.SubElement(joint, "dynamics", damping=_num(damping), friction=_num(friction))
        rotor = num(b.rotor_inertia)
        if rotor:
            rotors.append((b.joint_name or f"joint{i + 1}", rotor))
    for f in robot.frames:
        if f is root_frame:
            continue
        name = unique(f.name)
        ET.SubElement(root, "link", name=name)
        joint = ET.SubElement(root, "joint", name=unique(f"{f.name}_joint"), type="fixed")
        ET.SubElement(joint, "parent", link=link_of[f.parent])
        ET.SubElement(joint, "child", link=name)
        ET.SubElement(joint, "origin", xyz=_vec(num(x) for x in f.translation), rpy=_vec(rotation_rpy(mat(f.rotation))))
    if rotors:
        text = ", ".join(f"{j} {v!r}" for j, v in rotors)
        root.insert(1, ET.Comment(f" rotor (armature) inertia, not expressible in URDF: {text} "))
        warnings.warn(f"{robot.name}: URDF has no rotor inertia; the values are in a comment "
                      f"(Pinocchio: model.armature): {text}", stacklevel=2)
    ET.indent(root)
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
