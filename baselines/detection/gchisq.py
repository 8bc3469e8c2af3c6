"""Generalized chi-square tails: lives in :mod:`fdia_env.detection.gchisq`.

The detection game's expected reward needs them too, and the environments cannot depend on the
baselines, so the implementation is in the core package; this module re-exports it.
"""

from fdia_env.detection.gchisq import (  # noqa: F401
    NumericalAccuracyWarning,
    gchisq_cdf,
    gchisq_sf,
    gchisq_sf_mc,
    gchisq_tails,
    imhof_sf,
    quadratic_form_weights,
    quadratic_sf,
    quadratic_tails,
)
