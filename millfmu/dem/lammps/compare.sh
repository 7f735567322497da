#!/usr/bin/env bash
# Throughput of the annulus benchmark: millfmu.dem (numba) against LAMMPS (Debian's
# `lammps` package, pair gran/hertz/history + wall/gran) on the same cores, in one run.
# Installs Debian's lammps with apt-get if `lmp` is missing (needs root or sudo).
#
# Usage: compare.sh [NPROC]    (default 2: numba threads and MPI ranks)
# Environment: PYTHON (interpreter with millfmu installed, default python3),
#              LAMMPS_SKIN (neighbour skin for LAMMPS [m], default 0.4e-3),
#              REPEATS (runs of each code, alternating; the fastest of each counts,
#              default 3: on a shared machine single runs vary by tens of percent)
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
np="${1:-2}"
py="${PYTHON:-python3}"
skin="${LAMMPS_SKIN:-0.4e-3}"
repeats="${REPEATS:-3}"

if ! command -v lmp >/dev/null 2>&1; then
    echo "installing Debian's lammps ..." >&2
    if [ "$(id -u)" -eq 0 ]; then
        apt-get update -q && apt-get install -y -q lammps
    else
        sudo apt-get update -q && sudo apt-get install -y -q lammps
    fi
fi

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# OpenMPI refuses root unless told; harmless otherwise
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
lammps_loops=()
ours_runs=()
for ((k = 1; k <= repeats; k++)); do
    # one thread per MPI rank (set for LAMMPS only: numba's OpenMP layer would obey it too)
    (cd "$work" && OMP_NUM_THREADS=1 mpirun -np "$np" lmp -in "$here/in.annulus_bench" \
        -var skin "$skin" -log "$work/lammps.log" -screen none -nocite)
    lammps_atoms="$(awk '/^Created [0-9]+ atoms/ {print $2; exit}' "$work/lammps.log")"
    lammps_steps="$(awk '/^Loop time of/ {print $9; exit}' "$work/lammps.log")"
    lammps_loops+=("$(awk '/^Loop time of/ {print $4; exit}' "$work/lammps.log")")
    ours_runs+=("$(NUMBA_NUM_THREADS="$np" "$py" -c '
import json, sys
from millfmu.dem.bench import run_bench
r = run_bench(threads=int(sys.argv[1]))
print(json.dumps(r.__dict__))
' "$np")")
done
lammps_loop="$(printf '%s\n' "${lammps_loops[@]}" | sort -g | head -n 1)"
ours_json="$("$py" -c '
import json, sys
runs = [json.loads(a) for a in sys.argv[1:]]
best = min(runs, key=lambda r: r["loop_time_s"])
best["all_loop_times_s"] = [r["loop_time_s"] for r in runs]
print(json.dumps(best))
' "${ours_runs[@]}")"
echo "LAMMPS loop times [s]: ${lammps_loops[*]}" >&2

"$py" - "$lammps_atoms" "$lammps_loop" "$lammps_steps" "$ours_json" "$np" "$skin" <<'PYEOF'
import json, sys
atoms, loop, steps = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
ours = json.loads(sys.argv[4])
np_, skin = sys.argv[5], sys.argv[6]
lmp = atoms * steps / loop
print(f"annulus benchmark on {np_} cores ({np_} MPI ranks / {np_} numba threads), "
      f"fastest of the repeated runs of each")
print(f"  LAMMPS      : {atoms} beads, {steps} steps, loop {loop:.3f} s, "
      f"{lmp:.4g} particle-steps/s (skin {skin} m)")
print(f"  millfmu.dem : {ours['beads']} beads, {ours['steps']} steps, loop "
      f"{ours['loop_time_s']:.3f} s, {ours['particle_steps_per_s']:.4g} particle-steps/s "
      f"({ours['neighbour_builds']} neighbour builds; loop times "
      f"{', '.join(f'{t:.3f}' for t in ours['all_loop_times_s'])} s)")
print(f"  ratio millfmu.dem / LAMMPS: {ours['particle_steps_per_s'] / lmp:.3f}")
PYEOF
