"""Attack models: what the attacker's action means."""

from fdia_env.attacks.base import AttackEffect, AttackModel
from fdia_env.attacks.sparse import SparseAttack, mask_to_subset, subset_to_mask

__all__ = ["AttackEffect", "AttackModel", "SparseAttack", "mask_to_subset", "subset_to_mask"]
