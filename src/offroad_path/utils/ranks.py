"""Which process of a distributed training run this is. Lightning's DDP starts the other ranks by
running the stage's command again (or torchrun and SLURM start them all at once): only rank 0
claims and writes the stage's outputs and logs; the others train, test and end."""

from __future__ import annotations

from lightning.fabric.utilities.rank_zero import rank_zero_only


def is_global_zero() -> bool:
    """Rank 0, or not distributed at all (from RANK, LOCAL_RANK, SLURM_PROCID as Lightning reads them)."""
    return rank_zero_only.rank == 0
