"""Attack models: what the attacker's action means."""

from fdia_env.attacks.base import AttackEffect, AttackModel, bits_to_mask, mask_to_bits
from fdia_env.attacks.sparse import SparseAttack, trim_to_budget

__all__ = [
    "AttackEffect",
    "AttackModel",
    "SparseAttack",
    "bits_to_mask",
    "mask_to_bits",
    "trim_to_budget",
]
