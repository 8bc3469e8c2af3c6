"""Generalized chi-square tails (Imhof's method): lives in :mod:`fdia_env.detection.gchisq`.

The detection game's expected reward needs them too, and the environments cannot depend on the
baselines, so the implementation is in the core package; this module re-exports it.
"""

from fdia_env.detection.gchisq import (  # noqa: F401
    gchisq_sf,
    gchisq_sf_mc,
    quadratic_form_weights,
    quadratic_sf,
)
