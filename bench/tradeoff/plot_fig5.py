#!/usr/bin/python3
"""Draws the paper's Fig. 5 from `corofem_tradeoff fig5`: the load point's displacement components
against the force, for the linear, co-rotational and rigorous nonlinear (St. Venant-Kirchhoff,
Neo-Hookean) formulations, and reports where the co-rotational error passes 1 %, 5 % and 10 %.

    /usr/bin/python3 bench/tradeoff/plot_fig5.py fig5.csv --out docs/images/fig5_elbow.png

Error of a formulation A against a rigorous solution B at force P: |u_A(P) - u_B(P)| / |u_B(P)|
(Euclidean norm of the load point's displacement vector). The force where it first passes a
threshold is interpolated linearly between the two load increments around the crossing.
"""
import argparse
import csv
import math
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

NAMES = {"linear": "linear (clipped)", "corotational": "co-rotational (simplified, paper)",
         "stvk": "St. Venant-Kirchhoff (rigorous)", "neohookean": "Neo-Hookean (rigorous)"}
STYLE = {"linear": ("tab:gray", ":"), "corotational": ("tab:red", "-"), "stvk": ("tab:blue", "--"),
         "neohookean": ("k", "-.")}


def read(path):
    curves = defaultdict(lambda: {"P": [], "u": []})
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["status"] != "ok":
                continue
            c = curves[r["formulation"]]
            c["P"].append(float(r["force_N"]))
            c["u"].append([float(r["ux"]), float(r["uy"]), float(r["uz"])])
    return {k: (np.array(v["P"]), np.array(v["u"])) for k, v in curves.items()}


def relative_error(a, b):
    """Error of curve a against curve b at b's forces (a's forces must be the same increments)."""
    Pa, ua = a
    Pb, ub = b
    n = min(len(Pa), len(Pb))
    assert np.allclose(Pa[:n], Pb[:n]), "the curves must share their load increments"
    P = Pb[1:n]
    err = np.linalg.norm(ua[1:n] - ub[1:n], axis=1) / np.linalg.norm(ub[1:n], axis=1)
    return P, err


def crossing(P, err, level):
    """First force at which err reaches level (linear interpolation), None when never, or the
    negative of the first increment's force when it is already past the level there."""
    for i in range(len(P)):
        if err[i] >= level:
            if i == 0:
                return -float(P[0])
            t = (level - err[i - 1]) / (err[i] - err[i - 1])
            return float(P[i - 1] + t * (P[i] - P[i - 1]))
    return None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv")
    ap.add_argument("--out", default="docs/images/fig5_elbow.png")
    args = ap.parse_args()
    curves = read(args.csv)

    fig, axes = plt.subplots(1, 4, figsize=(17, 4.6))
    for k, comp in enumerate("xyz"):
        ax = axes[k]
        for name in ("linear", "corotational", "stvk", "neohookean"):
            if name not in curves:
                continue
            P, u = curves[name]
            colour, ls = STYLE[name]
            ax.plot(P, 1e3 * u[:, k], ls, color=colour, lw=1.6, label=NAMES[name])
        # Scale to the nonlinear curves: the linear one leaves the plot (it grows without bound).
        nl = [1e3 * curves[n][1][:, k] for n in ("corotational", "stvk", "neohookean") if n in curves]
        if nl:
            lo = min(0.0, min(v.min() for v in nl))
            hi = max(0.0, max(v.max() for v in nl))
            pad = 0.15 * (hi - lo if hi > lo else 1.0)
            ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlabel("force P (N)")
        ax.set_ylabel("displacement u_%s of the load point (mm)" % comp)
        ax.set_title("u_%s" % comp)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)

    ax = axes[3]
    levels = (0.01, 0.05, 0.10)
    report = []
    for name in ("corotational", "linear"):
        for rig in ("neohookean", "stvk"):
            if name not in curves or rig not in curves:
                continue
            P, err = relative_error(curves[name], curves[rig])
            colour, ls = STYLE[name]
            ax.plot(P, 100 * err, ls if rig == "neohookean" else "--", color=colour, lw=1.5,
                    label="%s vs %s" % (name, rig))
            xs = [crossing(P, err, lv) for lv in levels]
            report.append((name, rig, xs, float(P[-1]), float(err[-1])))
            if name == "corotational" and rig == "neohookean":
                for x, lv in zip(xs, levels):
                    if x is not None and x > 0:
                        ax.plot([x], [100 * lv], "o", color=colour, ms=5)
                        ax.annotate("%.0f N" % x, (x, 100 * lv), fontsize=7.5, xytext=(4, -10),
                                    textcoords="offset points", color=colour)
    if "stvk" in curves and "neohookean" in curves:
        P, err = relative_error(curves["stvk"], curves["neohookean"])
        ax.plot(P, 100 * err, ":", color="tab:blue", lw=1.5, label="stvk vs neohookean")
        report.append(("stvk", "neohookean", [crossing(P, err, lv) for lv in levels], float(P[-1]), float(err[-1])))
    for lv in levels:
        ax.axhline(100 * lv, color="gray", lw=0.8, alpha=0.6)
    ax.set_yscale("log")
    ax.set_xlabel("force P (N)")
    ax.set_ylabel("|u - u_rigorous| / |u_rigorous| (%)")
    ax.set_title("error of the load point's displacement")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5)
    fig.suptitle("Pipe elbow (sfepy elbow2.mesh, 8161 tets, E = 10 MPa, nu = 0.3), clamped at one end, "
                 "force P (1,0,1)/sqrt(2) on the other; reference backend, Cholesky", fontsize=10)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print("wrote %s" % args.out)

    def fmt(v):
        if v is None:
            return "not reached"
        return "< %.0f N (first increment)" % -v if v < 0 else "%.0f N" % v

    print("\n| error of | against | 1 % at | 5 % at | 10 % at | error at the largest force |")
    print("|---|---|---:|---:|---:|---:|")
    for name, rig, xs, Pmax, emax in report:
        print("| %s | %s | %s | %s | %s | %.2f %% at %.0f N |" % (name, rig, fmt(xs[0]), fmt(xs[1]), fmt(xs[2]),
                                                                100 * emax, Pmax))
    for name, (P, u) in sorted(curves.items()):
        print("%-13s P = %6.0f N: u = (%.2f, %.2f, %.2f) mm, |u| = %.2f mm" % (
            name, P[-1], 1e3 * u[-1, 0], 1e3 * u[-1, 1], 1e3 * u[-1, 2], 1e3 * np.linalg.norm(u[-1])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
