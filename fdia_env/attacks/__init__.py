"""Attack models: what the attacker's action means."""

from fdia_env.attacks.base import AttackEffect, AttackModel, bits_to_mask, mask_to_bits
from fdia_env.attacks.covariance import CovarianceAttack, CovarianceMap
from fdia_env.attacks.sparse import SparseAttack, trim_to_budget

__all__ = [
    "AttackEffect",
    "AttackModel",
    "CovarianceAttack",
    "CovarianceMap",
    "SparseAttack",
    "bits_to_mask",
    "mask_to_bits",
    "trim_to_budget",
]
