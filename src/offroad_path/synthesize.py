"""Stage `synthesize`: render the embedded synthetic stereo off-road world (see docs/design.md).

python -m offroad_path.synthesize [experiment=paper] [world/rig=gopro] [synthesize.sequences=4]
"""

from __future__ import annotations

import json
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.stage import hydra_stage, log, reads
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.outputs import Outputs
from offroad_path.world.classes import CLASS_NAMES
from offroad_path.world.record import record_sequences


def outputs(cfg: DictConfig) -> Outputs:
    return Outputs("synthesize", folders={"synthesize.out_dir": cfg.synthesize.out_dir})


@reads("synthesize", "world", writes=outputs)
def synthesize(cfg: DictConfig) -> list[dict]:
    out_dir = Path(cfg.synthesize.out_dir)
    with atomic_directory(out_dir, "synthesize", key="synthesize.out_dir") as tmp:
        summaries = record_sequences(cfg.world, cfg.synthesize.sequences, cfg.synthesize.seed, tmp, cfg.synthesize.workers)
        report = {"classes": list(CLASS_NAMES), "sequences": summaries}
        (tmp / "summary.json").write_text(json.dumps(report, indent=2) + "\n")
    frames = sum(s["frames"] for s in summaries)
    distance = sum(s["distance_m"] for s in summaries)
    log.info("wrote %d sequences (%d stereo frames, %.0f m driven) to %s", len(summaries), frames, distance, out_dir)
    return summaries


main = hydra_stage(synthesize)


if __name__ == "__main__":
    main()
