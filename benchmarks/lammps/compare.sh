#!/usr/bin/env bash
# The DEM bench against LAMMPS and LIGGGHTS on the same cores, in one run:
# `python -m benchmarks.dem_peers` (dense sheared bed, see benchmarks/dem_peers.py) with Debian's
# `lammps` and `liggghts` installed first where missing (apt-get; needs root or sudo) and
# OpenMPI's mpirun, which both use. The bench lives in the checkout, not in the installed
# package: it runs from the checkout's root.
#
# Usage: compare.sh [ARGS...]   (passed to the bench, e.g. --steps 500 --repeats 3)
# Environment: PYTHON (the interpreter with millfmu installed, default: the checkout's
# .venv/bin/python, else python3 on PATH)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../.." && pwd)"
py="${PYTHON:-}"
if [ -z "$py" ]; then
    if [ -x "$root/.venv/bin/python" ]; then py="$root/.venv/bin/python"; else py=python3; fi
fi

missing=()
command -v lmp >/dev/null 2>&1 || missing+=(lammps)
command -v liggghts >/dev/null 2>&1 || missing+=(liggghts)
command -v mpirun >/dev/null 2>&1 || missing+=(openmpi-bin)
if [ "${#missing[@]}" -gt 0 ]; then
    echo "installing Debian's ${missing[*]} ..." >&2
    sudo=""
    [ "$(id -u)" -eq 0 ] || sudo=sudo
    $sudo apt-get update -q
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q "${missing[@]}"
fi

cd "$root"
exec "$py" -m benchmarks.dem_peers "$@"
