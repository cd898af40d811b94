"""Which process of a distributed training run this is. Lightning's DDP starts the other ranks by
running the stage's command again (torchrun and SLURM start them all at once): only rank 0 claims
and writes the stage's outputs and logs; the others train, test and end."""

from __future__ import annotations

import os

# Where the launchers put the global rank, read in Lightning's order (lightning.fabric's
# rank_zero._get_rank), without importing it: the stages that never train start without torch.
RANK_VARIABLES = ("RANK", "LOCAL_RANK", "SLURM_PROCID", "JSM_NAMESPACE_RANK")


def is_global_zero() -> bool:
    """Rank 0, or not distributed at all."""
    for name in RANK_VARIABLES:
        if (rank := os.environ.get(name)) is not None:
            return int(rank) == 0
    return True
