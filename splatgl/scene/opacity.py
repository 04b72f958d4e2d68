"""Opacity logits at their limits.

A logit of +Inf is a fully opaque splat and -Inf a fully transparent one: sigmoid has a value
there.  PlayCanvas splat-transform (2.7 and 3.7) writes +Inf for opacity 1 when it turns a
compressed PLY's 255 into a PLY, so its PLYs of the shared scenes held 198-930 such rows, which
splatgl refused as NaN or Inf (and ``--drop-invalid`` dropped the most opaque splats).  They are
read as +-:data:`OPAQUE_LOGIT`, whose sigmoid rounds to exactly 1 (or 0) in float32, with one
warning a file (readers that go by blocks call this once a block).  NaN stays invalid.
"""

from __future__ import annotations

import warnings

import numpy as np

#: The finite logit an infinite one is read as: sigmoid(30) = 1 - 9.4e-14, 1.0 in float32.
OPAQUE_LOGIT = 30.0
#: The files already warned about in this process.
_WARNED: set[str] = set()


def finite_logits(path: object, logits: np.ndarray) -> np.ndarray:
    """``logits`` (N,) with +-Inf read as +-:data:`OPAQUE_LOGIT` (a new array, only where there
    are any, and the first time for ``path`` a warning counting those of these rows)."""
    infinite = np.isinf(logits)
    count = int(np.count_nonzero(infinite))
    if not count:
        return logits
    if str(path) not in _WARNED:
        _WARNED.add(str(path))
        warnings.warn(f"{path}: {count:,} of {logits.size:,} rows read hold an infinite opacity "
                      "logit (opacity exactly 1 or 0, as splat-transform writes it); read as "
                      f"+-{OPAQUE_LOGIT:g}", stacklevel=3)
    return np.where(infinite, np.copysign(OPAQUE_LOGIT, logits), logits).astype(logits.dtype)
