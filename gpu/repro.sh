#!/usr/bin/env bash
# The GPU preset's whole pipeline from nothing, in one go, on a GPU host without network
# (docs/scaling.md): the project's packages from an offline wheelhouse, then gpu/dvc.yaml with MLflow
# off and its independent stages side by side on the one GPU (tools/parallel_repro.py: --jobs at
# once, each with its share of the cores), each stage timed into gpu/metrics/pipeline_time.json as it
# finishes and the GPU's utilisation sampled every second into gpu/metrics/gpu_utilisation.csv; after
# a complete run its results page, docs/results-gpu.md; with --archive, one file of the lock, the
# metrics, the log and the page (a GPU host returns few files).
#
#   bash ../shared/gpu-host/wheelhouse.sh .whl --dvc     # where a package registry answers
#   bash gpu/repro.sh [--wheelhouse .whl] [--pipeline gpu/dvc.yaml] [--jobs 4] [--limit S] [--archive run.tgz]
#
# --limit S stops the pipeline S seconds after it started (a slot's end): the stages running then are
# stopped and their outputs removed (never half-written), the finished ones stay and are timed, and
# pipeline_time.json says `complete: false` and names the stopped ones; the exit status is then 124.
# python tools/gpu_cost.py says what the preset should take.
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
LIMIT=""
ARCHIVE=""
while [ $# -gt 0 ]; do
  [ $# -ge 2 ] || [ "${1#--}" = "$1" ] || { echo "error: $1: needs a value" >&2; exit 2; }
  case $1 in
    --wheelhouse) WHEELHOUSE=$2; shift 2 ;;
    --pipeline) PIPELINE=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --limit) LIMIT=$2; shift 2 ;;
    --archive) ARCHIVE=$2; shift 2 ;;
    *) echo "error: $1: unknown argument (--wheelhouse DIR, --pipeline FILE, --jobs N, --limit S, --archive FILE)" >&2; exit 2 ;;
  esac
done
ROOT=$(dirname "$PIPELINE")
# Every argument checked before anything is made: a refused run leaves nothing that refuses the corrected one.
[ -f "$PIPELINE" ] || { echo "error: $PIPELINE: no such pipeline" >&2; exit 2; }
[ "$(basename "$PIPELINE")" = dvc.yaml ] || { echo "error: --pipeline: $PIPELINE is not a pipeline file (a dvc.yaml)" >&2; exit 2; }
[[ "$JOBS" =~ ^[0-9]+$ && "$JOBS" -gt 0 ]] || { echo "error: --jobs: $JOBS is not a whole number above 0" >&2; exit 2; }
[ -z "$LIMIT" ] || [[ "$LIMIT" =~ ^[0-9]+$ && "$LIMIT" -gt 0 ]] || { echo "error: --limit: $LIMIT is not a whole number of seconds above 0" >&2; exit 2; }
[ -z "$ARCHIVE" ] || [ -d "$(dirname "$ARCHIVE")" ] || { echo "error: --archive: $(dirname "$ARCHIVE") is no folder" >&2; exit 2; }
[ -z "$ARCHIVE" ] || [ ! -e "$ARCHIVE" ] || { echo "error: --archive: $ARCHIVE exists; name a new file" >&2; exit 2; }
[ "$WHEELHOUSE" = none ] || [ -d "$WHEELHOUSE" ] || { echo "error: --wheelhouse: $WHEELHOUSE is no folder (or none)" >&2; exit 2; }
PAGE="docs/results-gpu.md"  # the GPU run's page, beside the laptop's; a rehearsal's stays in its folder
[ "$ROOT" = gpu ] || PAGE="$ROOT/results-$ROOT.md"
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
LIMITED=()
[ -n "$LIMIT" ] && LIMITED=(timeout "$LIMIT")
"${LIMITED[@]}" python3 tools/parallel_repro.py "$PIPELINE" --jobs "$JOBS" --log "$ROOT/pipeline_time.log" --json "$ROOT/metrics/pipeline_time.json" || status=$?
[ -n "$SAMPLER" ] && kill "$SAMPLER"
if [ "$status" = 0 ]; then  # a complete run: its results page, to commit beside the laptop's
  python3 -m offroad_path.report.readme --pipeline "$ROOT" --results "$PAGE"
elif [ "$status" = 124 ]; then
  echo "stopped at --limit $LIMIT s: the unfinished stages are named in $ROOT/metrics/pipeline_time.json" >&2
fi
if [ -n "$ARCHIVE" ]; then  # what the run measured, whether or not it finished
  kept=()
  for item in "$ROOT/dvc.lock" "$ROOT/metrics" "$ROOT/pipeline_time.log" "$PAGE"; do [ -e "$item" ] && kept+=("$item"); done
  tar czf "$ARCHIVE" "${kept[@]}"
  echo "archive: $ARCHIVE (${kept[*]})"
fi
exit "$status"
