"""What the fast-path tests share: how close a fast path must come to
the path it replaces."""

import numpy as np

RELATIVE = 1e-12
"""Largest relative difference allowed between two paths."""


def relative_difference(a, b):
    """max |a - b| over max |b| (b the reference)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)
