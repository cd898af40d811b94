# Sourced by gpu/repro.sh and gpu/measure.sh (from the repository root): `use_wheelhouse DIR` installs
# the project's packages from an offline wheelhouse (../shared/gpu-host/wheelhouse.sh builds one)
# into /tmp/site and puts them first on the paths; `use_wheelhouse none` keeps the environment as it is.
use_wheelhouse() {
  [ "$1" = none ] && return 0
  ls "$1"/*.whl >/dev/null 2>&1 || { echo "error: $1: holds no wheels (build them with wheelhouse.sh)" >&2; exit 2; }
  python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site "$1"/*.whl
  export PYTHONPATH=/tmp/site:$PWD/src PATH=/tmp/site/bin:$PATH  # /tmp/site first: its versions win
}
