#!/bin/bash
# The measurement behind the "auto" preconditioner (docs/performance.md, "The default
# preconditioner"): `corofem run` of beams of 360 to 12,960 tets, the SOFA liver, a soft 10,368-tet
# cube and 20 batched 2,000-tet cantilevers, on OpenCL (float) and the reference backend, with
# "diagonal" and "amg" in turns, ROUNDS rounds. Prints CSV (milliseconds a step: the median, and the
# mean, which holds amg's set-up at the first step). From the repository root, after building:
#
#   bash bench/precond_default.sh [ROUNDS] > precond_default.csv
set -u
rounds=${1:-2}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
/usr/bin/python3 - "$work/batch20.json" <<'PY'
import json, sys
bodies = []
for i in range(20):
    bodies.append({"name": f"b{i}",
                   "mesh": {"box": {"min": [0, 0, i * 0.2], "max": [0.4, 0.08, 0.1 + i * 0.2], "cells": [20, 4, 5], "tets_per_cell": 5}},
                   "material": {"youngs_modulus": 2e5 * (1 + 9 * i / 19), "poisson_ratio": 0.3, "density": 1000},
                   "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0], "tolerance": 1e-6}}],
                   "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]})
json.dump({"name": "batch20", "bodies": bodies, "solver": {"tolerance": 1e-6}, "output": {"vtk": False},
           "analysis": {"type": "dynamic", "time_step": 1 / 60, "steps": 20, "integrator": "backward_euler"}},
          open(sys.argv[1], "w"))
PY
echo "round,scene,backend,preconditioner,steps,median_ms,mean_ms,median_iterations,status"
run() {  # name scene backend preconditioner --set...
  local name=$1 scene=$2 backend=$3 pc=$4
  shift 4
  local out="$work/$name-$backend-$pc" extra=()
  [ "$backend" = opencl ] && extra=(--set solver.precision=float)
  rm -rf "$out"
  build/corofem run "$scene" --out "$out" --quiet --set backend="$backend" --set solver.preconditioner="$pc" \
      "${extra[@]}" "$@" > /dev/null 2>&1
  /usr/bin/python3 - "$out/summary.json" "$round,$name,$backend,$pc" <<'PY'
import json, sys
try:
    s = json.load(open(sys.argv[1]))
    w = s["wall_time_per_step_s"]
    print(f"{sys.argv[2]},{s['steps_taken']},{w['median'] * 1e3:.3f},{w['mean'] * 1e3:.3f},"
          f"{s['linear_iterations']['median_per_step']},{s['status']}")
except Exception as e:
    print(f"{sys.argv[2]},,,,,error: {e}")
PY
}
beam=bench/scenes/vega_beam.json
for round in $(seq "$rounds"); do
  for backend in opencl reference; do
    for pc in diagonal amg; do
      run beam360 $beam $backend $pc --set 'bodies.0.mesh.box.cells=[15,2,2]' --set analysis.steps=60
      run beam1620 $beam $backend $pc --set 'bodies.0.mesh.box.cells=[30,3,3]' --set analysis.steps=60
      run beam3840 $beam $backend $pc --set 'bodies.0.mesh.box.cells=[40,4,4]' --set analysis.steps=30
      run beam7500 $beam $backend $pc --set 'bodies.0.mesh.box.cells=[50,5,5]' --set analysis.steps=30
      run beam12960 $beam $backend $pc --set analysis.steps=30
      run liver samples/coupled_liver/liver.json $backend $pc --set analysis.steps=60 --set output.vtk=false
      run cube10k $beam $backend $pc --set 'bodies.0.mesh.box.max=[0.1,0.1,0.1]' \
          --set 'bodies.0.mesh.box.cells=[12,12,12]' --set bodies.0.material.youngs_modulus=1e5 \
          --set analysis.steps=20 --set 'output.probes=[]'
      run batch20 "$work/batch20.json" $backend $pc
    done
  done
done
