#!/usr/bin/env bash
# What sizing the GPU preset for ten minutes needs, measured in one go on a GPU host without network
# (docs/scaling.md): the torch renderer's stereo frames/s (benchmarks/render_speed.py), the
# trainings' images/s by batch size and with processes side by side (benchmarks/gpu_training.py),
# then the preset's pipeline from nothing (gpu/repro.sh) for the rest of --limit seconds, stopped
# there with the times of the stages it finished and the GPU's utilisation kept. Everything it
# measured lands in --out: the benchmarks' output, and run.tgz (gpu/repro.sh --archive) with the
# run's lock, metrics, log and (after a complete run) its results page. Its figures go into gpu/sizing.yaml.
#
#   bash gpu/measure.sh [--wheelhouse .whl] [--limit 540] [--jobs 4] --out DIR
#   bash gpu/measure.sh --wheelhouse none --rehearse --limit 300 --out /tmp/m   # the same steps on any machine, tiny
#
# --rehearse: rehearsal/dvc.yaml (experiment=rehearsal: the GPU preset's settings at the tour's sizes)
# and tiny benchmark sizes, on the GPU where there is one, else the CPU: the script checked before a GPU is at hand.
set -euo pipefail
cd "$(dirname "$0")/.."
WHEELHOUSE=.whl LIMIT=540 JOBS=4 OUT_DIR="" REHEARSE=0
while [ $# -gt 0 ]; do
  case $1 in
    --wheelhouse) WHEELHOUSE=$2; shift 2 ;;
    --limit) LIMIT=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --out) OUT_DIR=$2; shift 2 ;;
    --rehearse) REHEARSE=1; shift ;;
    *) echo "error: $1: unknown argument (--wheelhouse DIR, --limit S, --jobs N, --out DIR, --rehearse)" >&2; exit 2 ;;
  esac
done
[ -n "$OUT_DIR" ] || { echo "error: --out: required (the folder the figures are copied into)" >&2; exit 2; }
# Every argument checked before any work (a --limit timeout cannot take runs its benchmarks, then fails).
[[ "$LIMIT" =~ ^[0-9]+$ && "$LIMIT" -gt 0 ]] || { echo "error: --limit: $LIMIT is not a whole number of seconds above 0" >&2; exit 2; }
[[ "$JOBS" =~ ^[0-9]+$ && "$JOBS" -gt 0 ]] || { echo "error: --jobs: $JOBS is not a whole number above 0" >&2; exit 2; }
[ ! -e "$OUT_DIR/run.tgz" ] || { echo "error: --out: $OUT_DIR/run.tgz exists; name another folder" >&2; exit 2; }
[ "$WHEELHOUSE" = none ] || [ -d "$WHEELHOUSE" ] || { echo "error: --wheelhouse: $WHEELHOUSE is no folder (or none)" >&2; exit 2; }
PIPELINE=gpu/dvc.yaml RENDER=(--set render.backend=torch) TRAINING=()
if [ "$REHEARSE" = 1 ]; then
  PIPELINE=rehearsal/dvc.yaml
  RENDER=(--sequences 1 --frames 4 --set render.backend=torch world.width=128 world.height=72)
  TRAINING=(--width 0.125 --size 64x36 --batches 2 4 --processes 1 2 --seconds 1)
fi
ROOT=$(dirname "$PIPELINE")
for made in "$ROOT/data" "$ROOT/metrics" "$ROOT/dvc.lock"; do  # checked by gpu/repro.sh too: here before any minute is spent
  if [ -e "$made" ]; then echo "error: $made: exists; a run from nothing starts without it (move it away)" >&2; exit 2; fi
done
. gpu/wheelhouse_env.sh
use_wheelhouse "$WHEELHOUSE"
mkdir -p "$OUT_DIR"
START=$SECONDS
export PYTHONUNBUFFERED=1
python3 benchmarks/render_speed.py "${RENDER[@]}" 2>&1 | tee "$OUT_DIR/render_speed.txt"
python3 benchmarks/gpu_training.py "${TRAINING[@]}" --json "$OUT_DIR/gpu_training.json" 2>&1 | tee "$OUT_DIR/gpu_training.txt"
LEFT=$((LIMIT - (SECONDS - START)))
status=0
if [ "$LEFT" -gt 0 ]; then
  echo "the pipeline from nothing, for at most ${LEFT} s"
  # its lock, metrics (stage times, the GPU's utilisation), log and, after a complete run, results page in one archive
  bash gpu/repro.sh --wheelhouse none --pipeline "$PIPELINE" --jobs "$JOBS" --limit "$LEFT" --archive "$OUT_DIR/run.tgz" || status=$?
  echo "pipeline exit $status (124: stopped at the limit)"
else
  echo "error: the benchmarks took all of --limit $LIMIT s: the pipeline never started" >&2
  status=125
fi
# 124 (stopped at the limit) is what a measuring run expects; any other failure, or no pipeline at all, is not.
if [ "$status" != 0 ] && [ "$status" != 124 ]; then exit 1; fi
