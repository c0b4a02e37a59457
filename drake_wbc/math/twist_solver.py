"""The per-tick solver of the arm's Cartesian velocity controller
(Sec. III-A), in plain floats.

`TwistSolver` is drake_wbc.math.arm_control.joint_velocity_for_twist with its
limits and parameters checked once, for the controller's tick: the damped
least-squares solve (an LU solve at a regular point), then the joint-limit
bounds joint by joint, the uniform scaling to the velocity limits and to
the acceleration limit, the four stages of drake_wbc.math.arm_control's
docstring, in plain floats (the same command to the last bit given the
same least-squares q_dot). It returns a `JointVelocityCommand`. The
bounds of one joint towards one edge (`_PositionBounds`, with the braking
rate of an acceleration limit) and the SVD-based damped solve are shared
with drake_wbc.math.arm_control, which imports them from here.

Units as in drake_wbc.math.arm_control: J_a (6, n) in m/rad and rad/rad per
column, V_a in m/s and rad/s, joint angles in rad, rates in rad/s,
accelerations in rad/s^2, time steps in s.
"""

import math
from typing import NamedTuple

import numpy as np
from scipy.linalg.lapack import dgesdd as _gesdd
from scipy.linalg.lapack import dgesv as _gesv


class JointVelocityCommand(NamedTuple):
    """The result of `joint_velocity_for_twist`, with what shaped it.

    Attributes:
        q_dot: (n,) joint velocity command, rad/s.
        scale: the uniform factor in (0, 1] of the velocity limit (1 when
            no joint was too fast).
        acceleration_scale: the uniform factor in [0, 1] applied to the
            change from the previous q_dot (1 when within the acceleration
            limit or without one).
        limited_joints: (n,) bool, True for each joint whose rate was cut
            by its position limits.
        damping: lambda used by the least-squares solve (0 away from
            singularities).
        smallest_singular_value: s_min of J_a.
    """

    q_dot: np.ndarray
    scale: float
    acceleration_scale: float
    limited_joints: np.ndarray
    damping: float
    smallest_singular_value: float

    @property
    def damped(self):
        """True when the solve was damped (near a singularity)."""
        return self.damping > 0.0

    @property
    def limited(self):
        """True when a limit (position, velocity or acceleration) changed
        the damped least-squares solution."""
        return bool(self.scale < 1.0 or self.acceleration_scale < 1.0
                    or np.any(self.limited_joints))


def _damped_solve(U, s, Vt, V_a, lambda_):
    denominators = s**2 + lambda_**2
    safe = np.where(denominators > 0.0, denominators, 1.0)
    gains = np.where(denominators > 0.0, s / safe, 0.0)
    return Vt.T @ (gains * (U.T @ V_a))


def _braking_rate(distance, step, step_h):
    """The largest rate towards an edge `distance` away (>= 0) from which
    the joint can still stop at the edge, rates changing by at most
    step = a h a step (step_h = step h); floats.

    Braking from rate v = (m + f) a h (m an integer, 0 < f <= 1) at the
    full deceleration runs through v, v - a h, ..., f a h, then 0, and
    covers S(v) = a h^2 (m + 1)(f + m / 2). This inverts S: with
    D = distance / (a h^2), m(m + 1)/2 < D <= (m + 1)(m + 2)/2 and
    f = D / (m + 1) - m / 2. Since S(v - a h) = S(v) - v h, the bound one
    step later is exactly a h lower: braking along it never needs more
    than the acceleration limit, and S(v) >= v h keeps q + v h inside.
    """
    D = distance / step_h
    r = 0.5 * (math.sqrt(1.0 + 8.0 * D) - 1.0)  # r (r + 1) / 2 = D
    m = max(float(math.ceil(r)) - 1.0, 0.0)
    f = min(max(D / (m + 1.0) - 0.5 * m, 0.0), 1.0)
    return (m + f) * step


class _PositionBounds:
    """The joint-limit bounds of `joint_position_velocity_bounds`, one
    joint and one edge at a time, for arguments already checked: lower,
    upper (n,) float arrays, h and margin floats, acceleration_limit None
    or an (n,) float array."""

    def __init__(self, lower, upper, h, margin, acceleration_limit):
        self.h, self.margin = h, margin
        self.lower, self.upper = lower.tolist(), upper.tolist()
        # The band's upper edges, formed as upper - margin - q is.
        self.upper_band = (upper - margin).tolist()
        self.acceleration = acceleration_limit is not None
        if self.acceleration:
            step = acceleration_limit * h
            self.step, self.step_h = step.tolist(), (step * h).tolist()

    def rate(self, i, distance):
        """The bound on |q_dot_i| towards an edge `distance` away (rest
        at or beyond it): min(d / h, _braking_rate(d)), d >= 0."""
        distance = max(distance, 0.0)
        rate = distance / self.h
        if self.acceleration:
            rate = min(rate, _braking_rate(distance, self.step[i],
                                           self.step_h[i]))
        return rate


class TwistSolver(_PositionBounds):
    """`joint_velocity_for_twist` with its limits and parameters checked
    once, for the controller's tick: after the least-squares solve, the
    limits are applied joint by joint in plain floats, with the same
    operations as `joint_position_velocity_bounds` and the uniform
    scalings, so that the command is the same to the last bit given the
    same least-squares q_dot. A joint's bound is only computed on the side
    it moves towards (the other bound cannot cut it).

    At a regular point (s_min >= eps, J_a square) the least-squares
    solution is J_a^-1 V_a, taken by an LU solve after the singular values
    alone; otherwise by the thin SVD, as `damped_least_squares`. Both give
    the same q_dot to rounding.

    Args (checked by the caller, as joint_velocity_for_twist checks
    them): lower, upper, velocity_limit (n,) float arrays; h, lambda_max,
    eps, margin floats; acceleration_limit None or an (n,) float array.
    """

    def __init__(self, lower, upper, velocity_limit, h, lambda_max, eps,
                 margin, acceleration_limit):
        super().__init__(lower, upper, h, margin, acceleration_limit)
        self.lambda_max, self.eps = lambda_max, eps
        self._velocity_limit = velocity_limit.tolist()
        # Beyond the distance `clear` from an edge a joint's bound is at
        # least its velocity limit c (with a margin for rounding), so a
        # rate of at most c towards it is not cut: d / h >= c for
        # d >= c h and, braking, S(v) <= (v + a h / 2)^2 / (2 a) (the
        # maximum of a h^2 (m + 1)(f + m / 2) over f at a given v) so
        # that _braking_rate(d) >= c for d >= (c + a h / 2)^2 / (2 a).
        clear = velocity_limit * h
        if self.acceleration:
            self._change_limit = self.step
            clear = np.maximum(clear, (velocity_limit + 0.5 * self.h
                                       * acceleration_limit) ** 2
                               / (2.0 * acceleration_limit))
        self._clear = (clear * (1.0 + 1e-9) + 1e-300).tolist()

    def _bounded(self, q_dot, q, limited, bounds):
        """q_dot (list) clipped to the position bounds at q (list), joint
        by joint; sets limited[i] where it cuts. `bounds` remembers the
        bounds computed, by (joint, side)."""
        result = []
        for i, (v, q_i) in enumerate(zip(q_dot, q, strict=True)):
            if v > 0.0:
                distance = self.upper_band[i] - q_i
                if (v > self._velocity_limit[i]
                        or distance < self._clear[i]):
                    high = bounds.get((i, 1))
                    if high is None:
                        high = bounds[i, 1] = self.rate(i, distance)
                    if v > high:
                        v, limited[i] = high, True
            elif v < 0.0:
                distance = q_i - self.lower[i] - self.margin
                if (-v > self._velocity_limit[i]
                        or distance < self._clear[i]):
                    low = bounds.get((i, 0))
                    if low is None:
                        low = bounds[i, 0] = -self.rate(i, distance)
                    if v < low:
                        v, limited[i] = low, True
            result.append(v)
        return result

    def _least_squares(self, J, V):
        """(q_dot, lambda, s_min) of the damped least squares."""
        if J.shape[0] == J.shape[1]:
            s, info = _singular_values(J)
            if info == 0 and s[-1] >= self.eps:
                x, info = _lu_solve(J, V)
                if info == 0:
                    return x, 0.0, float(s[-1])
        U, s, Vt = np.linalg.svd(J, full_matrices=False)
        s_min = float(s[-1])
        # singularity_damping, inline.
        lambda_ = (0.0 if s_min >= self.eps
                   else float(self.lambda_max
                              * (1.0 - (s_min / self.eps) ** 2)))
        return _damped_solve(U, s, Vt, V, lambda_), lambda_, s_min

    def solve_floats(self, J, V, q, previous):
        """The command in floats: (q_dot, scale, acceleration_scale,
        limited_joints, damping, smallest_singular_value) as in
        JointVelocityCommand, with q_dot a list of floats and
        limited_joints a list of bools. J (6, n) and V (6,) float arrays,
        q and previous lists of n floats (previous ignored without an
        acceleration limit)."""
        x, lambda_, s_min = self._least_squares(J, V)
        limited = [False] * len(q)
        bounds = {}
        q_dot = self._bounded(x.tolist(), q, limited, bounds)

        scale = _scale_to(q_dot, self._velocity_limit)
        if scale != 1.0:
            q_dot = [scale * v for v in q_dot]

        acceleration_scale = 1.0
        if self.acceleration:
            change = [v - p for v, p in zip(q_dot, previous, strict=True)]
            acceleration_scale = _scale_to(change, self._change_limit)
            if acceleration_scale != 1.0:
                change = [acceleration_scale * c for c in change]
            q_dot = self._bounded(
                [p + c for p, c in zip(previous, change, strict=True)], q,
                limited, bounds)
        return q_dot, scale, acceleration_scale, limited, lambda_, s_min

    def solve(self, J, V, q, previous):
        """The JointVelocityCommand of joint_velocity_for_twist(J, V, q,
        ..., previous_q_dot=previous): float arrays (previous None
        without an acceleration limit)."""
        q_dot, scale, acceleration_scale, limited, lambda_, s_min = (
            self.solve_floats(J, V, q.tolist(),
                              None if previous is None
                              else previous.tolist()))
        return JointVelocityCommand(
            q_dot=np.array(q_dot),
            scale=scale,
            acceleration_scale=acceleration_scale,
            limited_joints=np.array(limited),
            damping=lambda_,
            smallest_singular_value=s_min,
        )


def _scale_to(vector, limits):
    """The largest factor in (0, 1] with |factor * vector_i| <= limits_i,
    for lists of floats."""
    scale = 1.0
    for value, limit in zip(vector, limits, strict=True):
        size = abs(value)
        if size > limit:
            scale = min(scale, limit / size)
    return scale


def _singular_values(J):
    """(s descending, info) of a square float matrix, by LAPACK gesdd."""
    _, s, _, info = _gesdd(J.T, compute_uv=0)  # J^T: no copy
    return s, info


def _lu_solve(J, V):
    """(J^-1 V, info) by LAPACK gesv."""
    _, _, x, info = _gesv(J, V)
    return x, info
