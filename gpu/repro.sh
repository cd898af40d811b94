#!/usr/bin/env bash
# The GPU preset's whole pipeline from nothing, in one go, on a GPU host without network
# (docs/scaling.md): the project's packages from an offline wheelhouse, then gpu/dvc.yaml with MLflow
# off and its independent stages side by side on the one GPU (tools/parallel_repro.py: --jobs at
# once, each with its share of the cores), each stage timed into gpu/metrics/pipeline_time.json as it
# finishes (a run stopped by a time limit keeps the times it measured, `complete: false`) and
# the GPU's utilisation sampled every second into gpu/metrics/gpu_utilisation.csv.
#
#   bash ../shared/gpu-host/wheelhouse.sh .whl --dvc     # where a package registry answers
#   bash gpu/repro.sh [--wheelhouse .whl] [--pipeline gpu/dvc.yaml] [--jobs 4]
#
# --jobs 1 runs the stages one by one, as `dvc repro gpu/dvc.yaml` does.
# --wheelhouse none uses the Python environment as it is (a host with every package installed).
# --pipeline rehearsal/dvc.yaml rehearses it: the GPU preset's settings on the tour's tiny worlds, on any machine.
# It refuses to start over outputs already there (the pipeline's data/, metrics/ or lock):
# it never deletes a run; move or remove it yourself.
set -euo pipefail
cd "$(dirname "$0")/.."
WHEELHOUSE=.whl
PIPELINE=gpu/dvc.yaml
JOBS=4
while [ $# -gt 0 ]; do
  case $1 in
    --wheelhouse) WHEELHOUSE=$2; shift 2 ;;
    --pipeline) PIPELINE=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    *) echo "error: $1: unknown argument (--wheelhouse DIR, --pipeline FILE, --jobs N)" >&2; exit 2 ;;
  esac
done
ROOT=$(dirname "$PIPELINE")
# Every argument checked before anything is made: a refused run leaves nothing that refuses the corrected one.
[ -f "$PIPELINE" ] || { echo "error: $PIPELINE: no such pipeline" >&2; exit 2; }
[ "$(basename "$PIPELINE")" = dvc.yaml ] || { echo "error: --pipeline: $PIPELINE is not a pipeline file (a dvc.yaml)" >&2; exit 2; }
[[ "$JOBS" =~ ^[0-9]+$ && "$JOBS" -gt 0 ]] || { echo "error: --jobs: $JOBS is not a whole number above 0" >&2; exit 2; }
[ "$WHEELHOUSE" = none ] || [ -d "$WHEELHOUSE" ] || { echo "error: --wheelhouse: $WHEELHOUSE is no folder (or none)" >&2; exit 2; }
for made in "$ROOT/data" "$ROOT/metrics" "$ROOT/dvc.lock"; do
  if [ -e "$made" ]; then echo "error: $made: exists; a run from nothing starts without it (move it away)" >&2; exit 2; fi
done
. gpu/wheelhouse_env.sh
use_wheelhouse "$WHEELHOUSE"
export OFFROAD_MLFLOW=false  # the presets read it (mlflow.enabled): no tracking store on the host
if ! git rev-parse --is-inside-work-tree >/dev/null 2>&1; then  # DVC needs a repository: a copy of the working tree has none
  git init -q && git add -A >/dev/null && git -c user.name=repro -c user.email=repro@localhost commit -qm "the run's tree"
fi
mkdir -p "$ROOT/metrics"
SAMPLER=""
if command -v nvidia-smi >/dev/null; then
  nvidia-smi --query-gpu=timestamp,utilization.gpu,memory.used --format=csv,noheader,nounits -l 1 >"$ROOT/metrics/gpu_utilisation.csv" &
  SAMPLER=$!
fi
stopped() {  # Ctrl-C or a kill: say so, stop the sampler, keep what the stages finished
  [ -n "$SAMPLER" ] && kill "$SAMPLER" 2>/dev/null
  echo "stopped: the stages finished so far are in $ROOT/metrics/pipeline_time.json (complete: false)" >&2
  exit 130
}
trap stopped INT TERM
status=0
python3 tools/parallel_repro.py "$PIPELINE" --jobs "$JOBS" --log "$ROOT/pipeline_time.log" --json "$ROOT/metrics/pipeline_time.json" || status=$?
[ -n "$SAMPLER" ] && kill "$SAMPLER"
exit "$status"
