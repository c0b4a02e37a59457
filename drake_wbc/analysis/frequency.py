"""Frequency responses of linear(ised) systems.

Drake has no Bode helper; these evaluate C (sI - A)^-1 B + D on the
imaginary axis, or on the unit circle z = e^(j omega h) for a system
discretised with period h, straight from the matrices that Drake's
`Linearize` returns.
"""

import numpy as np

from drake_wbc.validation import as_vector, non_negative


def frequency_response(A, B, C, D, omega, time_step=0.0):
    """Returns H(j omega) (or H(e^(j omega h))), shape (len(omega), p, m).

    Args:
        A, B, C, D: the state-space matrices (n x n, n x m, p x n, p x m).
        omega: angular frequencies in rad/s.
        time_step: 0 for a continuous system, else its period h in s.
    """
    A, B = np.atleast_2d(A), np.atleast_2d(B)
    C, D = np.atleast_2d(C), np.atleast_2d(D)
    omega = as_vector("omega", np.atleast_1d(omega))
    h = non_negative("time_step", time_step)
    points = np.exp(1j * omega * h) if h > 0 else 1j * omega
    eye = np.eye(A.shape[0])
    return np.array(
        [C @ np.linalg.solve(p * eye - A, B) + D for p in points]
    )


def linear_system_response(linear_system, omega, outputs=None):
    """The frequency response of a Drake LinearSystem (e.g. from
    `Linearize`), optionally with its own output matrix `outputs` (rows
    selecting states) in place of C and D = 0."""
    C, D = linear_system.C(), linear_system.D()
    if outputs is not None:
        C = np.atleast_2d(outputs)
        D = np.zeros((C.shape[0], linear_system.B().shape[1]))
    return frequency_response(linear_system.A(), linear_system.B(), C, D,
                              omega, linear_system.time_period())
