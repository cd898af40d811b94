"""Stage `synthesize`: render the embedded synthetic stereo off-road world (see docs/design.md).

python -m offroad_path.synthesize [experiment=paper] [world/rig=gopro] [synthesize.sequences=4]

The training drives seq_NNN, then the held-out test worlds test_NNN (offroad_path.world.held_out),
whose meta.json says "split": "test".
"""

from __future__ import annotations

import json
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from offroad_path.stage import hydra_stage, log, reads
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.tracking import flatten, stage_run
from offroad_path.world.classes import CLASS_NAMES
from offroad_path.world.held_out import choose_held_out_worlds
from offroad_path.world.record import Drive, record_sequences, sequence_seed


def outputs(cfg: DictConfig) -> Outputs:
    return Outputs("synthesize", folders={"synthesize.out_dir": cfg.synthesize.out_dir})


@reads("synthesize", "world", "render", "mlflow", writes=outputs)
def synthesize(cfg: DictConfig) -> list[dict]:
    out_dir = Path(cfg.synthesize.out_dir)
    with stage_run(cfg, "synthesize") as run, atomic_directory(out_dir, "synthesize", key="synthesize.out_dir") as tmp:
        synthesize_cfg = cfg.synthesize
        held_out = choose_held_out_worlds(cfg.world, synthesize_cfg.test_worlds, synthesize_cfg.seed, synthesize_cfg.workers)
        drives = [Drive(f"seq_{i:03d}", sequence_seed(synthesize_cfg.seed, i)) for i in range(synthesize_cfg.sequences)]
        drives += [Drive(w.name, w.seed, w.test_set, w.draw) for w in held_out]
        summaries = record_sequences(cfg.world, drives, tmp, synthesize_cfg.workers, cfg.render)
        tested = [
            {"name": w.name, "test_set": w.test_set, "blocks": w.blocks, "condition_groups": list(w.groups), "look_draw": w.draw}
            for w in held_out
        ]
        report = {"classes": list(CLASS_NAMES), "sequences": summaries, "test_worlds": tested}
        (tmp / "summary.json").write_text(json.dumps(report, indent=2) + "\n")
        frames = sum(s["frames"] for s in summaries)
        distance = sum(s["distance_m"] for s in summaries)
        if run is not None:
            import mlflow

            mlflow.log_params(flatten({"world": OmegaConf.to_container(cfg.world, resolve=True)}))
            mlflow.log_metrics({"sequences": len(summaries), "test_worlds": len(tested), "frames": frames, "distance_m": distance})
    log.info(
        "wrote %d sequences, %d of them held-out test worlds (%d stereo frames, %.0f m driven) to %s",
        len(summaries),
        len(tested),
        frames,
        distance,
        out_dir,
    )
    return summaries


main = hydra_stage(synthesize)
