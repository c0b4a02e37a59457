"""Frequency responses of linear(ised) systems, and what to read off them.

Drake has no Bode helper; these evaluate C (sI - A)^-1 B + D on the
imaginary axis, or on the unit circle z = e^(j omega h) for a system
discretised with period h, straight from the matrices that Drake's
`Linearize` returns, and read off a response its -3 dB bandwidth, its
peak gain and, for a loop transfer function, its gain and phase margins.

Plain numpy and scipy; the Drake side is in drake_wbc.analysis.chains
and drake_wbc.analysis.dmp_force_response.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from drake_wbc.math.validation import (
    as_matrix,
    as_vector,
    non_negative,
    positive,
    square_matrix,
)

DEFAULT_BAND_HZ = (0.01, 100.0)
"""The frequency band of the analysis in Hz: 0.01 to 100 Hz."""


def frequency_response(A, B, C, D, omega, time_step=0.0):
    """Returns H(j omega) (or H(e^(j omega h))), shape (len(omega), p, m).

    Args:
        A, B, C, D: the state-space matrices (n x n, n x m, p x n, p x m).
        omega: angular frequencies in rad/s.
        time_step: 0 for a continuous system, else its period h in s.
    """
    return response_function(A, B, C, D, time_step)(omega)


def response_function(A, B, C, D, time_step=0.0):
    """The function omega -> H at omega (as `frequency_response` returns
    it) of the system (A, B, C, D), prepared once for evaluating it at
    many frequencies (e.g. a margin's search): only the states that the
    inputs reach and the outputs see through A's nonzero entries
    (`coupled_states`) enter the solves. The others take no part in H,
    exactly (a state that no input reaches stays at zero, one that no
    output sees is not read), so H is the same; a controller's loop
    through the plant keeps about a quarter of its states.

    Args:
        A, B, C, D, time_step: as for `frequency_response`.
    """
    A, B, C, D = state_space(A, B, C, D)
    h = non_negative("time_step", time_step)
    keep = coupled_states(A, B, C) if A.size else np.zeros(0, dtype=int)
    A, B, C = A[np.ix_(keep, keep)], B[keep], C[:, keep]
    eye = np.eye(len(keep))

    def response(omega):
        omega = as_vector("omega", np.atleast_1d(omega))
        points = np.exp(1j * omega * h) if h > 0 else 1j * omega
        if not len(keep):
            return np.repeat(D[np.newaxis].astype(complex), len(omega),
                             axis=0)
        return np.array([C @ np.linalg.solve(p * eye - A, B) + D
                         for p in points])

    return response


def state_space(A, B, C, D):
    """The matrices A, B, C, D of a state-space system as finite float
    matrices of consistent shapes: A (n, n), B (n, m), C (p, n), D (p, m)
    (a vector or a number taken as a matrix of one row).

    Raises:
        ValueError: naming the matrix, its shape and the shape it must
            have, or its entries that are not finite.
    """
    A = square_matrix("A", np.atleast_2d(A))
    n = A.shape[0]
    B = as_matrix("B", np.atleast_2d(B), (n, None))
    C = as_matrix("C", np.atleast_2d(C), (None, n))
    D = as_matrix("D", np.atleast_2d(D), (C.shape[0], B.shape[1]))
    return A, B, C, D


def coupled_states(A, B, C):
    """The indices of the states that some input reaches and some output
    sees, through the nonzero entries of A (state j drives state i where
    A[i, j] != 0), B and C, in order."""
    links = A != 0.0

    def closure(start, links):
        reached = start.copy()
        while True:
            grown = reached | links[:, reached].any(axis=1)
            if (grown == reached).all():
                return reached
            reached = grown

    driven = closure(np.any(B != 0.0, axis=1), links)
    seen = closure(np.any(C != 0.0, axis=0), links.T)
    return np.nonzero(driven & seen)[0]


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


def frequency_grid(low_hz=DEFAULT_BAND_HZ[0], high_hz=DEFAULT_BAND_HZ[1],
                   points_per_decade=100):
    """A logarithmic grid of frequencies: (f in Hz, omega in rad/s).

    Args:
        low_hz, high_hz: the band's ends in Hz, 0 < low_hz < high_hz.
        points_per_decade: points per decade, >= 1 (the ends included).
    """
    low = positive("low_hz", low_hz)
    high = positive("high_hz", high_hz)
    if high <= low:
        raise ValueError(f"high_hz = {high!r} is not allowed with low_hz = "
                         f"{low!r}: must be greater")
    density = positive("points_per_decade", points_per_decade)
    if density < 1.0:
        raise ValueError(f"points_per_decade = {points_per_decade!r} is not "
                         "allowed: must be at least 1")
    count = max(2, int(np.ceil(density * np.log10(high / low))) + 1)
    hertz = np.logspace(np.log10(low), np.log10(high), count)
    return hertz, 2.0 * np.pi * hertz


def checked_grid(omega, minimum=2):
    """`omega` as a float vector of `minimum` or more increasing angular
    frequencies > 0 (rad/s), the grid of a response.

    Raises:
        ValueError: naming omega, its value and what is allowed.
    """
    omega = as_vector("omega", omega)
    if omega.size < minimum or not (
            omega[0] > 0.0 and np.all(np.diff(omega) > 0.0)):
        raise ValueError(f"omega = {omega!r} is not allowed: must hold "
                         f"{minimum} or more increasing frequencies > 0")
    return omega


def checked_response(omega, response):
    """`response` as a complex vector, one value for each frequency of
    `omega` (a checked grid).

    Raises:
        ValueError: naming response, its shape and the one it must have.
    """
    array = np.asarray(response)
    if array.shape != omega.shape:
        raise ValueError(
            f"response has shape {array.shape}, which is not allowed: must "
            f"have one value for each of the {omega.size} frequencies of "
            f"omega, shape {omega.shape}")
    return array


def decibels(response):
    """20 log10 |response| (-inf where the response is 0)."""
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.abs(response))


def phase_degrees(response, unwrap=True):
    """The phase of `response` (along its first axis) in degrees,
    unwrapped by default."""
    angle = np.angle(response)
    return np.degrees(np.unwrap(angle, axis=0) if unwrap else angle)


POWER_TOLERANCE = 0.05
"""How near a whole number n of `low_frequency_power` must be for the
response to count as |H| ~ omega^n at the grid's low end: within 0.05
of 0 its gain there is its DC gain to 0.25 dB (a first-order corner at
least 4.4 times higher); within 0.05 of -1 it integrates (a pole at
most a quarter of the lowest frequency, a time constant above about
70 s at 0.01 Hz, which the band cannot tell from one at DC)."""


def low_frequency_power(omega, response):
    """n of the response's low-frequency asymptote |H| ~ omega^n: the
    slope of log |H| over log omega between the grid's first two points
    (-1 for an integrator, 0 for a response with a finite, nonzero DC
    gain, 1 for a differentiator; between whole numbers where a pole or
    a zero lies near the grid's lowest frequency). NaN where the
    response is zero at both.

    Args:
        omega: (N,) increasing angular frequencies (rad/s), N >= 2.
        response: (N,) complex response at `omega`.
    """
    omega = checked_grid(omega)
    response = checked_response(omega, response)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.log(np.abs(response[:2]))
        return float((gain[1] - gain[0])
                     / (np.log(omega[1]) - np.log(omega[0])))


def dc_gain(omega, response):
    """|H| at DC, as far as the grid shows it (`low_frequency_power` n
    within POWER_TOLERANCE of a whole number):

    - n = 0 (flat at the grid's low end): the gain at its lowest
      frequency;
    - n = -1 (an integrator, such as eq. (tf-admit)'s D_a / s): inf;
    - n = 1, or a response zero there: 0;
    - otherwise (a pole or a zero near the grid's lowest frequency): nan,
      the DC gain lies below the band; the gain at the grid's lowest
      frequency would be a number of the grid, not of the system.

    Args:
        omega: (N,) increasing angular frequencies (rad/s), N >= 2.
        response: (N,) complex response at `omega`.
    """
    power = low_frequency_power(omega, response)
    if np.isnan(power):  # zero at both points
        return 0.0
    if abs(power) < POWER_TOLERANCE:
        return float(np.abs(np.asarray(response)[0]))
    if abs(power + 1.0) < POWER_TOLERANCE:
        return float("inf")
    if abs(power - 1.0) < POWER_TOLERANCE:
        return 0.0
    return float("nan")


def bandwidth(omega, response, reference=None, drop_db=3.0):
    """The -3 dB bandwidth: the lowest frequency at which the gain has
    fallen `drop_db` below `reference`, interpolated linearly in dB over
    log frequency between grid points.

    Args:
        omega: (N,) increasing angular frequencies (rad/s).
        response: (N,) complex response at `omega`.
        reference: the gain it is measured from; by default the DC gain
            (`dc_gain`) of a response flat at the grid's low end (a
            low-pass); a response with a pole or a zero at or near DC
            has no bandwidth from DC on the grid (nan).
        drop_db: how far the gain must fall, dB > 0.

    Returns:
        The bandwidth in rad/s, or nan if the gain never falls that far
        on the grid (nor is already below at its start), or there is no
        DC gain to fall from.
    """
    omega = checked_grid(omega)
    gain = decibels(checked_response(omega, response))
    drop = positive("drop_db", drop_db)
    if reference is None:
        reference = dc_gain(omega, response)
        if not 0.0 < reference < np.inf:
            return float("nan")
    level = 20.0 * np.log10(positive("reference", reference)) - drop
    below = np.nonzero(gain < level)[0]
    if len(below) == 0 or below[0] == 0:
        return float("nan")
    i = below[0]
    x0, x1 = np.log(omega[i - 1]), np.log(omega[i])
    fraction = (gain[i - 1] - level) / (gain[i - 1] - gain[i])
    return float(np.exp(x0 + fraction * (x1 - x0)))


def peak_gain(omega, response):
    """(the largest |response| on the grid, the frequency in rad/s where
    it is reached), on the grid `omega` (increasing frequencies > 0,
    rad/s) of `response`."""
    omega = checked_grid(omega, minimum=1)
    magnitude = np.abs(checked_response(omega, response))
    i = int(np.argmax(magnitude))
    return float(magnitude[i]), float(omega[i])


@dataclass
class StabilityMargins:
    """Margins of a loop transfer function L (the loop closed as
    y = L e, e = r - y).

    Attributes:
        gain_margin: 1 / |L| at the phase crossover (L real and negative)
            where |L| is largest; inf if the phase never crosses -180
            degrees on the band.
        phase_crossover: that frequency in rad/s (nan if none).
        phase_margin: 180 + arg L in degrees, in (-180, 180], at the gain
            crossover (|L| = 1) where it is smallest; inf if |L| never
            crosses 1 on the band.
        gain_crossover: that frequency in rad/s (nan if none).
    """

    gain_margin: float
    phase_crossover: float
    phase_margin: float
    gain_crossover: float

    @property
    def gain_margin_db(self):
        """The gain margin in dB, 20 log10 gain_margin."""
        return float(20.0 * np.log10(self.gain_margin))


def _crossings(function, omega, scale=None):
    """The roots of the real `function` of omega between the grid points
    where it changes sign, each refined with Brent's method; grid points
    where |function| <= 1e-12 scale(omega) count as roots (e.g. the
    Nyquist frequency of a discrete loop, where Im L vanishes to
    rounding)."""
    values = np.array([function(w) for w in omega])
    roots = [float(w) for w, v in zip(omega, values, strict=True)
             if scale is not None and abs(v) <= 1e-12 * scale(w)]
    for i in np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) <= 0)[0]:
        if values[i] == 0.0:
            roots.append(float(omega[i]))
        elif values[i + 1] != 0.0:
            roots.append(brentq(function, omega[i], omega[i + 1],
                                xtol=1e-14, rtol=1e-14))
    return sorted(set(roots))


def stability_margins(loop, omega, time_step=0.0):
    """Gain and phase margins of the loop transfer function `loop`.

    The crossovers are bracketed on the grid `omega` and refined to
    machine precision with Brent's method on `loop` itself, so the
    margins do not depend on the grid's density (only on its
    bracketing every crossover). The phase crossover is where Im L = 0
    with Re L < 0, which needs no unwrapping of the phase.

    Args:
        loop: a callable, omega (rad/s, a float) -> L (complex), e.g.
            lambda w: frequency_response(A, B, C, D, w, h)[0, 0, 0].
        omega: (N,) increasing angular frequencies bracketing the band.
        time_step: 0 for a continuous loop, else its period h in s: the
            grid is then cut at the Nyquist frequency pi / h, which ends
            it (above it a sampled loop repeats itself mirrored,
            L(2 pi / h - w) = conj L(w), and its crossovers' aliases
            would count, with the opposite phase margins).

    Returns:
        StabilityMargins.
    """
    if not callable(loop):
        raise ValueError(f"loop = {loop!r} is not allowed: must be a "
                         "callable of omega returning a complex number")
    omega = checked_grid(omega)
    h = non_negative("time_step", time_step)
    if h > 0.0:
        omega = np.append(omega[omega < np.pi / h], np.pi / h)

    def value(w):
        return complex(np.asarray(loop(w)).ravel()[0])

    phase_crossings = [
        w for w in _crossings(lambda w: value(w).imag, omega,
                              scale=lambda w: abs(value(w)))
        if value(w).real < 0.0]
    gain_crossings = _crossings(lambda w: abs(value(w)) - 1.0, omega)
    gain_margin, phase_crossover = float("inf"), float("nan")
    if phase_crossings:
        phase_crossover = max(phase_crossings, key=lambda w: abs(value(w)))
        gain_margin = 1.0 / abs(value(phase_crossover))
    phase_margin, gain_crossover = float("inf"), float("nan")
    for w in gain_crossings:
        margin = 180.0 + np.degrees(np.angle(value(w)))
        margin = margin - 360.0 if margin > 180.0 else margin
        if margin < phase_margin:
            phase_margin, gain_crossover = float(margin), float(w)
    return StabilityMargins(gain_margin, phase_crossover, phase_margin,
                            gain_crossover)
