"""Batched rigid-body dynamics: many states of one robot per call into C (see README.md here).

    from fmugen.batch import Kernels
    k = Kernels.from_urdf("ur5_robot.urdf", threads=2)
    qdd, dqdd_dq, dqdd_dqd, Minv = k.fd_derivatives(q, qd, tau)   # q, qd, tau: (N, n) float64
    u = k.unrolled()                                              # the same from code generated for the robot
"""
from .kernels import MASS_MATRIX_METHODS, Kernels, StateError, library
from .unrolled import UnrolledKernels

__all__ = ["Kernels", "UnrolledKernels", "StateError", "library", "MASS_MATRIX_METHODS"]
