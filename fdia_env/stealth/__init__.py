"""Stealthy false-data injection: bad-data detection on static DC state estimation.

See docs/guide/stealth.md.
"""

from fdia_env.stealth.static import (
    TESTS,
    StaticEstimation,
    check_alpha,
    sidak_threshold,
    static_estimation,
)

__all__ = ["TESTS", "StaticEstimation", "check_alpha", "sidak_threshold", "static_estimation"]
