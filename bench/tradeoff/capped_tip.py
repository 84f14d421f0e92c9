#!/usr/bin/python3
"""Capped PCG against converged PCG on the Vega beam (issue 29): how far the tip strays.

Runs bench/scenes/vega_beam.json (1 x 0.1 x 0.1 m, 12,960 tets, clamped at x = 0, gravity,
backward Euler at 1/60 s, reference backend, a probe "tip" on the plane x = 1) with `corofem run`
once converged (tolerance 1e-6, max_iterations 3000, preconditioner "amg": the reference answer)
and then with each setting below, and prints one Markdown table row per setting:

  tip error  max over steps |tip - tip_ref| / max over steps |tip_ref| (3-vectors, Euclidean),
             over the steps both runs took;
  status     summary.json's status ("ok", "ok_unconverged" or a failure), steps_taken, and the
             steps whose solves stopped at the cap short of the tolerance (steps_unconverged);
  pcg/step   median PCG iterations per step (a step retried in substeps counts all of them);
  ms/step    median wall time per step.

Usage, from the repository root after building (build/corofem):

  /usr/bin/python3 bench/tradeoff/capped_tip.py                # 200 steps, about 3 minutes
  /usr/bin/python3 bench/tradeoff/capped_tip.py --steps 20     # a quick look

A run that fails (nonzero exit status) is still read: its summary.json and probes.csv hold the
steps it completed.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

# (label, preconditioner, max_iterations, further --set overrides); the first is the reference.
RUNS = [
    ("amg, converged (reference)", "amg", 3000, []),
    ("amg, cap 20", "amg", 20, []),
    ("amg, cap 10", "amg", 10, []),
    ("amg, cap 5", "amg", 5, []),
    ("warped_cholesky, converged", "warped_cholesky", 3000, []),
    ("warped_cholesky, cap 20", "warped_cholesky", 20, []),
    ("warped_cholesky, cap 10", "warped_cholesky", 10, []),
    ("warped_cholesky, cap 5", "warped_cholesky", 5, []),
    ("diagonal, converged", "diagonal", 3000, []),
    ("diagonal, cap 20", "diagonal", 20, []),
    ("diagonal, cap 20, max_substeps 8", "diagonal", 20, ["analysis.max_substeps=8"]),
]


def run(corofem, scene, out, steps, preconditioner, max_iterations, extra):
    cmd = [corofem, "run", scene, "--out", out, "--quiet",
           "--set", f"analysis.steps={steps}",
           "--set", f"solver.preconditioner={preconditioner}",
           "--set", f"solver.max_iterations={max_iterations}"]
    for e in extra:
        cmd += ["--set", e]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    summary_path = os.path.join(out, "summary.json")
    if not os.path.exists(summary_path):
        sys.exit(f"{' '.join(cmd)}: no summary.json (exit {proc.returncode}):\n{proc.stderr}")
    with open(summary_path) as f:
        summary = json.load(f)
    data = np.genfromtxt(os.path.join(out, "probes.csv"), delimiter=",", names=True)
    data = np.atleast_1d(data)
    tip = np.column_stack([data["tip_ux"], data["tip_uy"], data["tip_uz"]])
    steps_col = data["step"].astype(int)
    return {"cmd": " ".join(cmd), "rc": proc.returncode, "summary": summary, "steps": steps_col, "tip": tip,
            "stderr": proc.stderr.strip()}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--corofem", default="build/corofem")
    p.add_argument("--scene", default="bench/scenes/vega_beam.json")
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--out", default="", help="folder for the runs' outputs (default: a temporary one)")
    args = p.parse_args()
    out_root = args.out or tempfile.mkdtemp(prefix="capped_tip_")

    results = []
    for i, (label, pre, cap, extra) in enumerate(RUNS):
        r = run(args.corofem, args.scene, os.path.join(out_root, f"run{i}_{pre}_{cap}"), args.steps, pre, cap, extra)
        r["label"] = label
        results.append(r)
        print(f"# ran: {r['cmd']} (exit {r['rc']})", file=sys.stderr, flush=True)

    ref = results[0]
    if ref["summary"]["status"] != "ok":
        sys.exit(f"the reference run did not converge: {ref['summary']['status']}\n{ref['stderr']}")
    ref_tip = {k: t for k, t in zip(ref["steps"], ref["tip"]) if k > 0}  # step 0: the common start
    ref_scale = np.max(np.linalg.norm(ref["tip"], axis=1))

    print(f"reference: max over steps |tip| = {ref_scale:.4f} m; final tip (x, y, z) = "
          f"({ref['tip'][-1][0]:.4f}, {ref['tip'][-1][1]:.4f}, {ref['tip'][-1][2]:.4f}) m\n")
    print("| run | status | steps taken | unconverged steps | tip error (max over steps) | at step | "
          "error at the last step | pcg/step | ms/step |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in results:
        s = r["summary"]
        common = [k for k in r["steps"] if k in ref_tip]
        diffs = np.array([np.linalg.norm(r["tip"][list(r["steps"]).index(k)] - ref_tip[k]) for k in common])
        worst = int(np.argmax(diffs)) if len(diffs) else 0
        if len(diffs):
            cells = [f"{100 * diffs[worst] / ref_scale:.3g} %", str(common[worst]), f"{100 * diffs[-1] / ref_scale:.3g} %",
                     f"{s['linear_iterations']['median_per_step']:g}",
                     f"{1000 * s['wall_time_per_step_s']['median']:.0f}"]
        else:
            cells = ["-"] * 5  # no step completed
        print(f"| {r['label']} | {s['status']} | {s['steps_taken']}/{s['steps_requested']} | "
              f"{s['convergence']['steps_unconverged']} | " + " | ".join(cells) + " |")
    failed = [r for r in results if r["summary"]["status"] not in ("ok", "ok_unconverged")]
    for r in failed:
        print(f"\n{r['label']}: {r['stderr'].splitlines()[-1] if r['stderr'] else r['summary']['status']}")
    print(f"\noutputs in {out_root}")


if __name__ == "__main__":
    main()
