#!/usr/bin/python3
"""Draws the speed-accuracy trade measured by `corofem_tradeoff sweep`.

    /usr/bin/python3 bench/tradeoff/plot_tradeoff.py tradeoff.csv --out-dir docs/images [--markdown]

One PNG per scene (docs/images/tradeoff_<scene>.png): the displacement error (left) and the energy
error (right) against the median wall time per step, log-log. The Pareto front on the displacement
error (no other setting is both faster and more accurate) is drawn as a line and its points are
ringed. An error of exactly 0 (the reference setting itself) is drawn at the floor 1e-16. Failed
runs are not drawn; they are listed. Prints the front settings of every scene (--markdown: as a
Markdown table for docs/tradeoff.md).
"""
import argparse
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

FLOOR = 1e-16


def read_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def num(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def label(r):
    """Short description of one setting."""
    parts = [r["backend"]]
    if r["backend"] != "reference":
        parts.append(r["precision"])
        if r["rotation"] != "polar":
            parts.append(r["rotation"])
    if r["linear_solver"] == "cholesky":
        parts.append("cholesky")
    else:
        parts.append({"none": "pcg", "diagonal": "pcg+diag", "block_diagonal": "pcg+block",
                      "amg": "pcg+amg", "warped_cholesky": "pcg+warped"}[r["preconditioner"]])
        parts.append("tol=%g" % num(r["tolerance"]))
        if int(r["max_iterations"]) < 1000:
            parts.append("cap=%s" % r["max_iterations"])
    if r["formulation"] != "corotational":
        parts.append(r["formulation"])
    return " ".join(parts)


def pareto(points):
    """Indices of the points (t, e) that no other point beats in both: sorted by time, the running
    minimum of the error (a point must improve on it by more than 0.1 %). Ties in time keep the
    smaller error."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best * (1 - 1e-3):  # a gain below 0.1 % is noise, not a better setting
            front.append(i)
            best = points[i][1]
    return front


def style(r):
    """Colour by backend and precision, marker by the knob that differs from the baseline."""
    colour = {"reference": "tab:blue", ("opencl", "float"): "tab:orange", ("opencl", "mixed"): "tab:purple",
              ("opencl", "double"): "tab:green"}
    c = colour["reference"] if r["backend"] == "reference" else colour[(r["backend"], r["precision"])]
    if r["formulation"] == "linear":
        m = "x"
    elif r["linear_solver"] == "cholesky":
        m = "*"
    elif r["rotation"] != "polar":
        m = {"svd": "v", "quaternion": "^", "qr": "<"}[r["rotation"]]
    elif int(r["max_iterations"]) < 1000:
        m = {"amg": "p", "warped_cholesky": "X"}.get(r["preconditioner"], "s")
    else:
        m = {"none": "o", "diagonal": "D", "block_diagonal": "P", "amg": "h", "warped_cholesky": ">"}[r["preconditioner"]]
    return c, m


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("csv")
    ap.add_argument("--out-dir", default="docs/images")
    ap.add_argument("--markdown", action="store_true", help="print the fronts as Markdown tables")
    args = ap.parse_args()
    rows = read_rows(args.csv)
    os.makedirs(args.out_dir, exist_ok=True)
    scenes = []
    for r in rows:
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    for scene in scenes:
        srows = [r for r in rows if r["scene"] == scene]
        ok = [r for r in srows if r["status"] == "ok" and not math.isnan(num(r["disp_error"]))]
        failed = [r for r in srows if r not in ok]
        multi_mesh = len({r["mesh"] for r in ok}) > 1
        name = (lambda r: label(r) + " @" + r["mesh"]) if multi_mesh else label

        t = [num(r["ms_per_step"]) for r in ok]
        e = [max(num(r["disp_error"]), FLOOR) for r in ok]
        en = [max(num(r["energy_error"]), FLOOR) for r in ok]
        front = pareto(list(zip(t, e)))

        fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
        for ax, err, title in ((axes[0], e, "displacement error (relative L2)"),
                               (axes[1], en, "energy error (relative)")):
            for i, r in enumerate(ok):
                c, m = style(r)
                ax.scatter(t[i], err[i], color=c, marker=m, s=42, alpha=0.85, zorder=3)
            ft = [t[i] for i in front]
            fe = [err[i] for i in front]
            if ax is axes[0]:
                ax.step(ft, fe, where="post", color="k", lw=1.2, zorder=2, label="Pareto front")
            ax.scatter(ft, fe, facecolors="none", edgecolors="k", s=120, lw=1.2, zorder=4)
            ax.set_xscale("log")
            ax.set_yscale("log")
            if max(t) / min(t) < 300:  # few decades: label the minor ticks too (2, 3, 5 ...)
                fmt = matplotlib.ticker.FuncFormatter(lambda v, _: "%g" % v)
                ax.xaxis.set_minor_formatter(fmt)
                ax.xaxis.set_major_formatter(fmt)
                ax.tick_params(axis="x", which="minor", labelsize=7)
            ax.set_xlabel("median wall time per step (ms)")
            ax.set_ylabel(title)
            ax.grid(True, which="both", alpha=0.3)
        ref = srows[0]["reference"]
        axes[0].set_title("%s: error vs time (reference: %s)" % (scene, ref))
        axes[1].set_title("%s: energy error (ringed: displacement front)" % scene)
        # Legend: colours and markers.
        from matplotlib.lines import Line2D
        handles = [Line2D([], [], color="tab:blue", marker="o", ls="", label="reference (Eigen, double)"),
                   Line2D([], [], color="tab:orange", marker="o", ls="", label="OpenCL float"),
                   Line2D([], [], color="tab:purple", marker="o", ls="", label="OpenCL mixed (float, double dots)"),
                   Line2D([], [], color="tab:green", marker="o", ls="", label="OpenCL double"),
                   Line2D([], [], color="gray", marker="*", ls="", label="Cholesky"),
                   Line2D([], [], color="gray", marker="o", ls="", label="PCG, no precond."),
                   Line2D([], [], color="gray", marker="D", ls="", label="PCG + diagonal"),
                   Line2D([], [], color="gray", marker="P", ls="", label="PCG + block diagonal"),
                   Line2D([], [], color="gray", marker="h", ls="", label="PCG + multigrid (amg)"),
                   Line2D([], [], color="gray", marker=">", ls="", label="PCG + warped Cholesky"),
                   Line2D([], [], color="gray", marker="s", ls="", label="PCG iteration cap (block)"),
                   Line2D([], [], color="gray", marker="p", ls="", label="PCG iteration cap (amg)"),
                   Line2D([], [], color="gray", marker="X", ls="", label="PCG iteration cap (warped)"),
                   Line2D([], [], color="gray", marker="v", ls="", label="rotation svd"),
                   Line2D([], [], color="gray", marker="^", ls="", label="rotation quaternion"),
                   Line2D([], [], color="gray", marker="<", ls="", label="rotation qr"),
                   Line2D([], [], color="gray", marker="x", ls="", label="linear formulation"),
                   Line2D([], [], color="k", lw=1.2, label="Pareto front")]
        axes[1].legend(handles=handles, fontsize=7.5, loc="best", ncol=2)
        if multi_mesh:
            # Annotate each mesh's Cholesky point so the resolution axis can be read.
            for i, r in enumerate(ok):
                if r["linear_solver"] == "cholesky" and r["formulation"] == "corotational":
                    axes[0].annotate(r["mesh"], (t[i], e[i]), fontsize=7, xytext=(4, 4), textcoords="offset points")
        fig.tight_layout()
        out = os.path.join(args.out_dir, "tradeoff_%s.png" % scene)
        fig.savefig(out, dpi=110)
        plt.close(fig)

        print("\n## %s (%d settings, %d failed) -> %s" % (scene, len(ok), len(failed), out))
        if args.markdown:
            print("\n| setting | mesh | ms/step | disp. error | energy error | PCG it./step |")
            print("|---|---|---:|---:|---:|---:|")
            for i in front:
                r = ok[i]
                print("| %s | %s | %.3g | %.2g | %.2g | %.3g |" % (label(r), r["mesh"], t[i], num(r["disp_error"]),
                                                                 num(r["energy_error"]), num(r["iterations"])))
        else:
            for i in front:
                r = ok[i]
                print("  front: %-52s %-12s %9.3f ms  disp %.3g  energy %.3g" % (
                    label(r), r["mesh"], t[i], num(r["disp_error"]), num(r["energy_error"])))
        for r in failed:
            print("  failed: %-51s %-12s %s" % (label(r), r["mesh"], r["status"][:110]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
