#!/usr/bin/env bash
# The DEM bench against LAMMPS and LIGGGHTS on the same cores, in one run:
# `millfmu dem bench` (dense sheared bed, see millfmu/dem/studies/bench.py) with Debian's `lammps`
# and `liggghts` installed first where missing (apt-get; needs root or sudo) and OpenMPI's
# mpirun, which both use.
#
# Usage: compare.sh [ARGS...]   (passed to `millfmu dem bench`, e.g. --steps 500 --repeats 3)
# Environment: MILLFMU (the millfmu command, default: millfmu on PATH, else .venv/bin/millfmu)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
root="$(cd "$here/../../.." && pwd)"
cmd="${MILLFMU:-}"
if [ -z "$cmd" ]; then
    if command -v millfmu >/dev/null 2>&1; then cmd=millfmu; else cmd="$root/.venv/bin/millfmu"; fi
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

exec "$cmd" dem bench "$@"
