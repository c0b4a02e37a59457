"""Argument checks that fail early and say exactly what was wrong.

Every public function of the math layer checks its inputs with these helpers,
so that a bad value is reported where it enters, with the argument's name,
the value received and what is allowed, instead of surfacing later as a NaN
in a command to the robot. Each helper returns the checked value as a
float numpy array (or float), ready to use.

The parameter dataclasses check (and normalise) their fields in
`__post_init__`. They are plain, mutable dataclasses, so that Drake's
`yaml_load_typed` can fill them field by field
(drake_wbc.controller.parameters); after
assigning fields, `validate` runs every check of a parameters tree again.
Parameters are checked where they enter (their dataclasses, at load and
build time) and a stage reads what it needs from them when it is built,
without checking them again: changing a parameters object afterwards has
no effect on the stages already built from it.
"""

import copy
import dataclasses
import math
import re

import numpy as np

from drake_wbc.math.scalar_support import value_of


def _shown(value):
    """A short, readable rendering of a value for an error message, on
    one line (a matrix's rows side by side)."""
    text = np.array2string(np.asarray(value), precision=6, threshold=20,
                           max_line_width=math.inf).replace("\n", "")
    return text if len(text) <= 200 else text[:197] + "..."


def as_vector(name, value, size=None):
    """Returns `value` as a finite float vector, optionally of a given size.

    Raises:
        ValueError: naming `name` when the value is not a 1-D array of
            `size` finite numbers.
    """
    return _as_array(name, value, (size,), "vector")


def as_matrix(name, value, shape):
    """Returns `value` as a finite float matrix of `shape`.

    An entry None in `shape` accepts any size along that axis, e.g.
    (6, None) for a Jacobian with six rows.

    Raises:
        ValueError: naming `name` when the shape is wrong or an entry is not
            finite.
    """
    return _as_array(name, value, shape, "matrix")


def square_matrix(name, value):
    """Returns `value` as a finite float matrix of shape (n, n).

    Raises:
        ValueError: naming `name` when it is not square, or an entry is
            not finite.
    """
    matrix = as_matrix(name, value, (None, None))
    if matrix.shape[0] != matrix.shape[1]:
        raise ValueError(f"{name} has shape {matrix.shape}, which is not "
                         "allowed: must be square (n, n)")
    return matrix


def as_float_array(name, value, shape):
    """as_vector / as_matrix for a value that is usually right already:
    a float64 ndarray of exactly `shape` with finite entries is returned
    as it is (no copy), anything else goes through the full check, which
    names `name` on a bad value.

    Args:
        name: the argument's name, for the error message.
        value: the argument.
        shape: the wanted shape, e.g. (6,) or (6, 9).

    Raises:
        ValueError: as as_vector / as_matrix.
    """
    # A sum of floats is finite only if every term is (a finite sum that
    # overflows goes through the full check, which passes it).
    if (type(value) is np.ndarray and value.dtype == np.float64
            and value.shape == shape
            and math.isfinite(sum(value.ravel().tolist()))):
        return value
    if len(shape) == 1:
        return as_vector(name, value, shape[0])
    return as_matrix(name, value, shape)


_NOT_NUMBERS = (str, bytes, bool, np.bool_)
"""What numpy and float() take for numbers and a check must not: "15"
and b"15" (a quoted number in a file), True and False."""


def _holds_non_number(value):
    """Whether `value`, a number or a (nested) sequence or array of them,
    has a string or a boolean anywhere (np.asarray([1.0, True], float)
    would take it for 1.0)."""
    if isinstance(value, _NOT_NUMBERS):
        return True
    if isinstance(value, np.ndarray | np.generic):
        if value.dtype.kind in "bSU":
            return True
        return value.dtype == object and any(
            _holds_non_number(v) for v in np.ravel(value))
    if isinstance(value, list | tuple):
        return any(_holds_non_number(v) for v in value)
    return False


def _as_array(name, value, shape, kind, finite=True):
    """`value` as a float array of `shape` (a string or boolean refused),
    every entry finite where `finite` (else unchecked: the caller's)."""
    # Arrays of numbers, the usual case, hold no string or boolean.
    if not (type(value) is np.ndarray and value.dtype.kind in "fiu") and (
            _holds_non_number(value)):
        raise ValueError(
            f"{name} = {value!r} is not allowed: must be a {kind} of "
            "numbers (not strings or booleans)")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} = {value!r} is not allowed: must be a {kind} of numbers"
        ) from None
    fits = array.ndim == len(shape) and all(
        wanted is None or size == wanted
        for size, wanted in zip(array.shape, shape, strict=False)
    )
    if not fits:
        wanted = ", ".join("any" if n is None else str(n) for n in shape)
        wanted += "," if len(shape) == 1 else ""
        raise ValueError(
            f"{name} = {_shown(array)} has shape {array.shape}, which is "
            f"not allowed: must have shape ({wanted})"
        )
    if finite and not np.all(np.isfinite(array)):
        raise ValueError(
            f"{name} = {_shown(array)} is not allowed: "
            "every entry must be finite (no NaN or infinity)"
        )
    return array


def as_scalar(name, value):
    """Returns `value` as a finite float.

    Raises:
        ValueError: naming `name` when the value is not one finite number
            (a string or a boolean is not one, whatever float() makes of
            it).
    """
    if _holds_non_number(value):
        raise ValueError(
            f"{name} = {value!r} is not allowed: must be a single number "
            "(not a string or a boolean)")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} = {value!r} is not allowed: must be a single number"
        ) from None
    if not np.isfinite(number):
        raise ValueError(
            f"{name} = {number!r} is not allowed: must be finite"
        )
    return number


def in_closed_range(name, value, lower, upper):
    """Returns `value` as a float after checking lower <= value <= upper.

    Raises:
        ValueError: naming `name`, its value and the allowed range.
    """
    number = as_scalar(name, value)
    if not lower <= number <= upper:
        raise ValueError(
            f"{name} = {number!r} is not allowed: "
            f"must lie in [{lower}, {upper}]"
        )
    return number


def unit_interval(name, value):
    """Returns `value`, a float or AutoDiffXd scalar, as it is after
    checking 0 <= value <= 1 (a NaN fails): the check of an input port's
    value that the port's size cannot constrain (a weighting factor, a
    transition value, a switch), for every scalar type of a stage.

    Raises:
        ValueError: naming `name`, its value and the allowed range.
    """
    if not 0.0 <= value <= 1.0:
        number = float(value_of(value))
        raise ValueError(
            f"{name} = {number!r} is not allowed: must lie in [0, 1]")
    return value


def whole_number(name, value, minimum=0, maximum=None, hint=""):
    """`value` as an int >= `minimum` and, unless `maximum` is None, <=
    `maximum` (811.0 is accepted; a bool is not); `hint` ends the
    message of one too large.

    Raises:
        ValueError: naming `name`, its value (a whole one as an integer)
            and what is allowed.
    """
    if isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} = {value!r} is not allowed: must be a "
                         "whole number")
    number = as_scalar(name, value)
    if not number.is_integer():
        raise ValueError(f"{name} = {value!r} is not allowed: must be a "
                         "whole number")
    if number < minimum:
        raise ValueError(f"{name} = {int(number)} is not allowed: must be "
                         f"{minimum} or greater")
    if maximum is not None and number > maximum:
        raise ValueError(f"{name} = {int(number)} is not allowed: must be "
                         f"at most {maximum}{hint}")
    return int(number)


def boolean(name, value):
    """Returns `value` as a bool after checking that it is True or False
    (numpy's bools too; not 0, 1 or a string).

    Raises:
        ValueError: naming `name` and its value.
    """
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} = {value!r} is not allowed: must be true "
                         "or false")
    return bool(value)


def text(name, value):
    """Returns `value` after checking that it is a string.

    Raises:
        ValueError: naming `name` and its value.
    """
    if not isinstance(value, str):
        raise ValueError(f"{name} = {value!r} is not allowed: must be a "
                         "string")
    return value


def _first(bad):
    """The index of the first True entry of the bool array `bad` (the
    entry a check's error names), or None."""
    found = np.flatnonzero(bad)
    return int(found[0]) if found.size else None


def selection(name, value, size):
    """Returns `value` as a vector of `size` entries, each exactly 0 or 1
    (the diagonal of a selection matrix such as S_m, or a switch such as
    S_hri with size 1).

    Raises:
        ValueError: naming `name`, its value and the first bad entry.
    """
    vector = as_vector(name, np.atleast_1d(value), size)
    i = _first((vector != 0.0) & (vector != 1.0))
    if i is not None:
        raise ValueError(
            f"{name} = {_shown(vector)} is not allowed: every entry must "
            f"be 0 or 1 (here {name}[{i}] = {float(vector[i])!r})")
    return vector


def whole_multiple(name, value, period_name, period, tolerance=1e-9):
    """Returns `value` as a float after checking that it is a whole
    multiple (1, 2, ...) of `period` > 0, to a relative `tolerance`.

    Raises:
        ValueError: naming both, their values and what is allowed.
    """
    number = positive(name, value)
    base = positive(period_name, period)
    ratio = number / base
    if ratio < 1.0 - tolerance or abs(ratio - round(ratio)) > tolerance:
        raise ValueError(
            f"{name} = {number!r} s is not allowed with {period_name} = "
            f"{base!r} s: must be a whole multiple (1, 2, ...) of it")
    return number


def robots_own(name, value):
    """Returns `value`, a parameter whose default (None) stands for the
    robot's own value; None here, in a stage built alone, is an error
    naming it: build_controller fills it in from the robot's description
    (drake_wbc.controller.parameters.for_robot), a stage alone has no
    robot to read it from."""
    if value is None:
        raise ValueError(
            f"{name} = None is not allowed here: None stands for the "
            "robot's own value, which build_controller fills in from the "
            "robot's description; a stage built alone must be given it")
    return value


def positive(name, value):
    """Returns `value` as a float after checking that it is > 0.

    Raises:
        ValueError: naming `name` and its value.
    """
    return _above(name, value, strict=True)


SITE_EXTENT = 1000.0
"""The largest coordinate or size of anything in a scene, m (an obstacle,
a person's path, the robot's start, a movement's start and goal): a
scene is the robot's surroundings, which its LIDARs see to 25 m; Drake's
geometry squares sizes and distances, and aborts on a cylinder 1e300 m
high."""


def within_site(name, value, lengths=None):
    """`value` (m; a number or a vector) after checking that every entry
    (or every entry of `lengths`, its parts in m) lies within
    +-SITE_EXTENT.

    Raises:
        ValueError: naming `name`, its value and what is allowed.
    """
    array = np.asarray(value if lengths is None else lengths, dtype=float)
    if np.any(np.abs(array) > SITE_EXTENT):
        raise ValueError(
            f"{name} = {value!r} is not allowed: every coordinate and size "
            f"of a scene must lie within +-{SITE_EXTENT:g} m (the site "
            "around the robot)")
    return value


LONGEST_RUN = 3600.0
"""s: the longest simulated run a command accepts (an hour).
A run keeps its logs in memory, about 80 kB a simulated second (100
signals at 100 Hz), and simulates at a few times real time: an hour is
some 300 MB of log and a quarter of an hour of waiting a run. A longer
one (`--duration 1e300`) would run for ever and end out of memory. A
deployment keeps no log of its own and has a bound of its own
(drake_wbc.deployment.deploy.LONGEST_DEPLOYMENT)."""


def positive_duration(name, value, longest=LONGEST_RUN, hint=""):
    """Returns `value`, a duration in s, as a float after checking that
    it is finite, > 0 and at most `longest` (a command's --duration, a
    scenario's duration); `hint` ends the message of one too long.

    Raises:
        ValueError: naming `name` and its value.
    """
    number = as_scalar(name, value)
    if not number > 0.0:
        raise ValueError(f"{name} = {number!r} is not allowed: must be > 0 s")
    if number > longest:
        raise ValueError(
            f"{name} = {number!r} is not allowed: must be at most "
            f"{longest:g} s ({_spoken(longest)}){hint}")
    return number


def _spoken(seconds):
    """`seconds` as a person says it: "an hour", "7 days", "10 minutes"."""
    if seconds == 3600.0:
        return "an hour"
    if seconds % 86400.0 == 0.0:
        days = seconds / 86400.0
        return "a day" if days == 1.0 else f"{days:g} days"
    if seconds % 3600.0 == 0.0:
        return f"{seconds / 3600.0:g} hours"
    return f"{seconds / 60.0:g} minutes"


def non_negative(name, value):
    """Returns `value` as a float after checking that it is >= 0.

    Raises:
        ValueError: naming `name` and its value.
    """
    return _above(name, value, strict=False)


def _above(name, value, strict):
    number = as_scalar(name, value)
    if not (number > 0.0 if strict else number >= 0.0):
        wanted = "greater than 0" if strict else "0 or greater"
        raise ValueError(
            f"{name} = {number!r} is not allowed: must be {wanted}"
        )
    return number


def limit_vector(name, value, size=None, infinity=math.inf):
    """`value` as a float vector of `size` entries (any if None), each
    finite or equal to `infinity` (-inf for lower limits, inf for upper
    ones): a limit that bounds nothing on that side.

    Raises:
        ValueError: naming `name` and the first entry that is NaN or the
            other infinity, or when the shape is wrong.
    """
    array = _as_array(name, value, (size,), "vector", finite=False)
    i = _first(~np.isfinite(array) & (array != infinity))
    if i is not None:
        raise ValueError(
            f"{name}[{i}] = {float(array[i])!r} is not allowed: must be "
            f"finite, or {infinity!r} (no limit on that side)")
    return array


def ordered_limits(lower_name, lower, upper_name, upper, size=None,
                   unlimited=False):
    """Returns (lower, upper) as vectors after checking lower < upper.

    Works for scalars too (pass size=None and numbers): the result is then
    a pair of 1-element vectors.

    Args:
        lower_name, upper_name: the limits' names, for the error.
        lower, upper: the limits.
        size: the number of entries, any if None.
        unlimited: whether an entry may be unlimited: -inf below and +inf
            above together (a continuous joint, which has no position
            limits). A limit infinite on one side only is refused either
            way; every other entry is finite.

    Raises:
        ValueError: naming both arguments and the first index where the
            lower limit is not below the upper one, or (with `unlimited`)
            where one of them is infinite and the other not its opposite.
    """
    if not unlimited:
        lower = as_vector(lower_name, np.atleast_1d(lower), size)
        upper = as_vector(upper_name, np.atleast_1d(upper), lower.shape[0])
    else:
        lower = limit_vector(lower_name, np.atleast_1d(lower), size,
                             -math.inf)
        upper = limit_vector(upper_name, np.atleast_1d(upper),
                             lower.shape[0], math.inf)
        i = _first(np.isinf(lower) != np.isinf(upper))
        if i is not None:
            raise ValueError(
                f"{lower_name}[{i}] = {float(lower[i])!r} and "
                f"{upper_name}[{i}] = {float(upper[i])!r} are not allowed: "
                "each pair must be finite, or -inf and inf together (a "
                "continuous joint, without position limits)")
    i = _first(lower >= upper)
    if i is not None:
        raise ValueError(
            f"{lower_name}[{i}] = {float(lower[i])!r} and {upper_name}[{i}] "
            f"= {float(upper[i])!r} are not allowed: each lower limit must be "
            "strictly below its upper limit"
        )
    return lower, upper


def rotation_matrix(name, value, tolerance=1e-6):
    """Returns `value` as a 3x3 rotation matrix after checking R^T R = I and
    det R = +1 to `tolerance`.

    Raises:
        ValueError: naming `name` when the matrix is not a proper rotation.
    """
    R = as_matrix(name, value, (3, 3))
    orthogonality = np.max(np.abs(R.T @ R - np.eye(3)))
    determinant = np.linalg.det(R)
    if orthogonality > tolerance or abs(determinant - 1.0) > tolerance:
        raise ValueError(
            f"{name} = {_shown(R)} is not allowed: must be a rotation matrix "
            f"(R^T R = I and det R = 1 to {tolerance}; here the largest "
            f"entry of R^T R - I is {orthogonality:.3g} and det R = "
            f"{determinant:.6g})"
        )
    return R


def validate(params, path=""):
    """Runs the checks of the parameters dataclass `params` again, and those
    of every dataclass nested in it (also as items of a list or tuple, e.g.
    a scene's obstacles), innermost first; returns `params`.

    The checks are each class's `__post_init__`, which also normalises the
    values (e.g. a list into a read-only array or a tuple), so they are
    safe to run more than once. They are needed again after fields have
    been assigned, as `yaml_load_typed` does.

    Args:
        params: a dataclass instance.
        path: the dotted name of `params` in an enclosing tree, if any
            (e.g. "arm_cdmp"), used in error messages.

    Raises:
        ValueError: naming the field by its dotted path from the root
            (e.g. `arm_cdmp.S_m = [0.5 1. 1. 1. 1. 1.] is not allowed: ...`).
    """
    if not _is_instance(params):
        name = path or "params"
        raise ValueError(f"{name} = {params!r} is not allowed: must be a "
                         "parameters dataclass")
    prefix = f"{path}." if path else ""
    names = [f.name for f in dataclasses.fields(params)]
    for name in names:
        value = getattr(params, name)
        if _is_instance(value):
            validate(value, prefix + name)
        elif isinstance(value, (list, tuple)):
            for i, item in enumerate(value):
                if _is_instance(item):
                    validate(item, f"{prefix}{name}[{i}]")
    check = getattr(params, "__post_init__", None)
    if check is None:
        return params
    try:
        check()
    except ValueError as error:
        raise ValueError(_qualified(str(error), prefix, names)) from None
    return params


def _is_instance(value):
    """True for a dataclass instance (not a dataclass type)."""
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def validated_copy(params):
    """A deep copy of the parameters dataclass `params`, validated (see
    `validate`): what a stage keeps, so that later changes to `params`
    do not reach it."""
    return validate(copy.deepcopy(params))


def _qualified(message, prefix, names):
    """`message` with the fields `names` it reports (`name = ...`,
    `name[i] = ...`, `name.sub[j].x = ...`, `name has shape ...`,
    `name is missing`) renamed
    `prefix + name`; the message is prefixed with the path instead when it
    reports no field."""
    if not prefix:
        return message
    pattern = re.compile(
        r"(?<![\w.])(" + "|".join(map(re.escape, names))
        + r")(?=(?:\[\d+\]|\.\w+)* (?:=|has shape|is missing))")
    renamed, count = pattern.subn(lambda m: prefix + m.group(1), message)
    return renamed if count else f"{prefix[:-1]}: {message}"


def checked_instance(name, value, kind, default):
    """`value` if it is a `kind`, `default()` if it is None; else raises a
    ValueError naming `name`."""
    if value is None:
        return default()
    if not isinstance(value, kind):
        raise ValueError(
            f"{name} = {value!r} is not allowed: must be a {kind.__name__} "
            "or None"
        )
    return value


def positive_vector(name, value, size):
    """`value` as a vector of `size` finite entries, each > 0.

    Raises:
        ValueError: naming `name`, the first bad entry and what is allowed.
    """
    vector = as_vector(name, value, size)
    i = _first(vector <= 0.0)
    if i is not None:
        raise ValueError(
            f"{name}[{i}] = {float(vector[i])!r} is not allowed: every entry "
            "must be greater than 0")
    return vector
