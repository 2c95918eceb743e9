"""Robot descriptions: the immutable contract, robot files, checks, the N-link chain.

* :mod:`.description` -- ``Robot`` (a tree of ``Body``, named ``Frame``), ``Link`` (DH),
  ``Parameter``, ``Payload``, ``dh_to_joints``;
* :mod:`.expressions` -- the safe parser of quantities in robot files;
* :mod:`.loader`      -- ``load_robot_description(path)`` (TOML or URDF -> Robot);
* :mod:`.urdf`        -- ``load_urdf(path)`` (hardened URDF reader);
* :mod:`.urdf_export` -- ``robot_to_urdf(robot)`` (any Robot as URDF);
* :mod:`.checks`      -- physical checks and ``RobotFileError``;
* :mod:`.chain`       -- ``n_link_chain(n, ...)`` and ``chain_to_toml(robot)``.
"""
from .chain import chain_to_toml, n_link_chain
from .checks import RobotFileError, UnrealisableInertiaWarning
from .description import (MODIFIED, PRISMATIC, REVOLUTE, STANDARD, Body, Frame, Limits, Link, Parameter, Payload,
                          Robot, dh_to_joints)
from .expressions import ExpressionError
from .loader import load_robot_description, robot_from_toml

__all__ = [
    "Robot",
    "Body",
    "Frame",
    "Limits",
    "dh_to_joints",
    "Link",
    "Parameter",
    "Payload",
    "REVOLUTE",
    "PRISMATIC",
    "STANDARD",
    "MODIFIED",
    "load_robot_description",
    "robot_from_toml",
    "n_link_chain",
    "chain_to_toml",
    "RobotFileError",
    "UnrealisableInertiaWarning",
    "ExpressionError",
]
