"""Robot descriptions: the immutable contract, robot files, checks, the N-link chain.

* :mod:`.description` -- ``Robot``, ``Link``, ``Parameter``, ``Payload``;
* :mod:`.expressions` -- the safe parser of quantities in robot files;
* :mod:`.loader`      -- ``load_robot_description(path)`` (TOML -> Robot);
* :mod:`.checks`      -- physical checks and ``RobotFileError``;
* :mod:`.chain`       -- ``n_link_chain(n, ...)`` and ``chain_to_toml(robot)``.
"""
from .chain import chain_to_toml, n_link_chain
from .checks import RobotFileError, UnrealisableInertiaWarning
from .description import MODIFIED, PRISMATIC, REVOLUTE, STANDARD, Link, Parameter, Payload, Robot
from .expressions import ExpressionError
from .loader import load_robot_description, robot_from_toml

__all__ = [
    "Robot",
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
