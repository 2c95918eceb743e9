"""Newton-Euler (DYNAMAN) and recursive Lagrange (thesis) give the same M and h,
and both equal an independent numpy implementation of the nest balances."""
import warnings

import numpy as np
import pytest
import sympy as sp

import fmugen
from fmugen.dynamics.manipulator import Manipulator
from fmugen.robot.chain import n_link_chain
from fmugen.robot.loader import robot_from_toml, load_robot_description
from numeric_oracle import inverse_dynamics as oracle_id
from symbolic_zero import is_identically_zero


def load(name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # puma_thesis opts in to its unrealisable link 2
        return load_robot_description(f"robots/{name}.toml")


@pytest.mark.parametrize("n,joints", [(2, "RP"), (3, "RPR")])
def test_formulations_agree_symbolically(n, joints):
    arm = Manipulator(n_link_chain(n, joints, symbolic=True))
    Mn, hn = arm.closed_form("newton_euler")
    Ml, hl = arm.closed_form("lagrange")
    angles = [q for q, L in zip(arm.q, arm.robot.links) if L.joint == "revolute"]
    for e in list(Mn - Ml) + list(hn - hl):
        assert is_identically_zero(e, angles)


def test_symbolic_zero_test_can_fail():
    q = sp.Symbol("q")
    assert is_identically_zero(sp.sin(q) ** 2 + sp.cos(q) ** 2 - 1, [q])
    assert not is_identically_zero(sp.sin(q) ** 2 - sp.cos(q) ** 2, [q])


def modified_copy(robot):
    """The same arm in Craig's convention (a, alpha moved to the next link's entry).

    Standard A_i = Rz Tz Tx(a_i) Rx(alpha_i); in the modified convention link
    i+1 carries a_i, alpha_i.  Inertial data are given in the DH frame, which
    differs between the conventions, so they are rotated/shifted accordingly:
    frame L_i(standard) = F_i(modified) Tx(a_i) Rx(alpha_i).
    """
    from fmugen.robot.description import Link, Robot

    links = robot.links
    out = []
    for i, L in enumerate(links):
        prev = links[i - 1] if i else None
        Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(L.alpha), -sp.sin(L.alpha)], [0, sp.sin(L.alpha), sp.cos(L.alpha)]])
        com = Rx * sp.Matrix(L.com) + sp.Matrix([L.a, 0, 0])
        I = Rx * sp.Matrix(L.inertia_com) * Rx.T
        out.append(Link(name=L.name, joint=L.joint, a=prev.a if prev else 0, alpha=prev.alpha if prev else 0,
                        d=L.d, theta=L.theta, mass=L.mass, com=tuple(com),
                        inertia_com=tuple(tuple(I.row(r)) for r in range(3)), rotor_inertia=L.rotor_inertia,
                        damping=L.damping, external_wrench=L.external_wrench))
    return Robot(name=robot.name + "_mdh", convention="modified", links=tuple(out), gravity=robot.gravity,
                 parameters=robot.parameters)


CASES = ["puma_thesis", "puma_thesis_com", "stanford_arm", "chain5_RRP_seed3", "chain7_RPRRP_seed11",
         "chain6_mixed_modified"]


def robot_case(name):
    if name.startswith("chain5"):
        return n_link_chain(5, "RRP", seed=3)
    if name.startswith("chain7"):
        return n_link_chain(7, "RPRRP", seed=11)
    if name == "chain6_mixed_modified":
        return modified_copy(n_link_chain(6, "RPR", seed=5))
    return load(name)


@pytest.mark.parametrize("name", CASES)
def test_formulations_and_oracle_agree_numerically(name):
    robot = robot_case(name)
    arm = Manipulator(robot)
    rng = np.random.default_rng(42)
    n = robot.n
    for _ in range(3):
        q, qd, qdd = rng.normal(size=(3, n))
        tau_ne = arm.inverse_dynamics(q, qd, qdd)
        tau_la = arm.inverse_dynamics(q, qd, qdd, formulation="lagrange")
        tau_or = oracle_id(robot, q, qd, qdd)
        scale = np.abs(tau_or).max()
        assert np.abs(tau_ne - tau_la).max() <= 1e-10 * scale
        assert np.abs(tau_ne - tau_or).max() <= 1e-10 * scale
        M_ne, M_la = arm.mass_matrix(q), arm.mass_matrix(q, formulation="lagrange")
        assert np.abs(M_ne - M_la).max() <= 1e-10 * np.abs(M_ne).max()
        h_ne, h_la = arm.bias(q, qd), arm.bias(q, qd, formulation="lagrange")
        assert np.abs(h_ne - h_la).max() <= 1e-10 * np.abs(h_ne).max()
        # the three functions are consistent: tau = M qdd + h
        assert np.abs(M_ne @ qdd + h_ne - tau_ne).max() <= 1e-10 * scale


def test_modified_convention_describes_the_same_arm():
    robot = n_link_chain(5, "RRPRR", seed=9)
    a, b = Manipulator(robot), Manipulator(modified_copy(robot))
    rng = np.random.default_rng(1)
    q, qd, qdd = rng.normal(size=(3, 5))
    for f in fmugen.FORMULATIONS:
        assert np.allclose(a.inverse_dynamics(q, qd, qdd), b.inverse_dynamics(q, qd, qdd, formulation=f),
                           rtol=1e-11, atol=1e-11)


def test_rotor_inertia_and_damping_enter_as_joint_terms():
    plain_text = open("robots/puma_thesis_com.toml").read()
    text = plain_text.replace("[[links]]", "[[links]]\nrotor_inertia = 0.3\ndamping = 1.5")
    arm, plain = Manipulator(robot_from_toml(text, "puma_rotors")), Manipulator(robot_from_toml(plain_text, "puma"))
    rng = np.random.default_rng(3)
    q, qd = rng.normal(size=(2, 6))
    for f in fmugen.FORMULATIONS:
        dM = arm.mass_matrix(q, formulation=f) - plain.mass_matrix(q, formulation=f)
        assert np.allclose(dM, 0.3 * np.eye(6), rtol=0, atol=1e-12)
        dh = arm.bias(q, qd, formulation=f) - plain.bias(q, qd, formulation=f)
        assert np.allclose(dh, 1.5 * qd, rtol=0, atol=1e-11)


def test_payload_and_external_wrench_against_oracle():
    text = open("robots/puma_thesis_com.toml").read()
    text = text.rstrip() + "\n\n[payload]\nmass = 2.0\ncom = [0.01, 0.02, 0.1]\n"
    text = text.replace('name = "flange"', 'name = "flange"\nexternal_wrench = true')
    robot = robot_from_toml(text, "puma_extras")
    assert robot.links[-1].external_wrench and robot.payload is not None
    arm = Manipulator(robot)
    rng = np.random.default_rng(7)
    q, qd, qdd = rng.normal(size=(3, 6))
    ext = rng.normal(size=6) * 10
    tau_or = oracle_id(robot, q, qd, qdd, ext)
    scale = np.abs(tau_or).max()
    for f in fmugen.FORMULATIONS:
        assert np.abs(arm.inverse_dynamics(q, qd, qdd, ext, formulation=f) - tau_or).max() <= 1e-10 * scale
    # the payload really is there: without it the torques differ
    plain = Manipulator(load("puma_thesis_com"))
    assert np.abs(plain.inverse_dynamics(q, qd, qdd) - arm.inverse_dynamics(q, qd, qdd)).max() > 1e-3 * scale
