#!/usr/bin/python3
"""Draws the paper's Fig. 8 from two corofem runs of samples/fig8_beam/fig8_beam.json.

    /usr/bin/python3 samples/fig8_beam/plot_fig8.py --corot out/fig8_corot --linear out/fig8_linear \
        --out out/fig8_beam.png

Panels: (a) initial shape, (b) co-rotational, (c) linear, all in one scale (side view, x-y), and
(d) the tip's vertical displacement over time for both. Everything comes from the runs' own
outputs: the last .vtu of each <body>.pvd series and probes.csv. Prints the volume change of each
final shape (the paper's "artificial enlargement" of the linear formulation).
"""
import argparse
import csv
import os
import sys
import xml.etree.ElementTree as ET

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read_pvd(path):
    """(time, file) entries of a ParaView collection, in order."""
    root = ET.parse(path).getroot()
    out = []
    for ds in root.iter("DataSet"):
        out.append((float(ds.get("timestep")), os.path.join(os.path.dirname(path), ds.get("file"))))
    return out


def read_vtu(path):
    """Points (n x 3) and tetrahedra (m x 4) of an ASCII VTK XML unstructured grid."""
    root = ET.parse(path).getroot()
    piece = root.find("UnstructuredGrid/Piece")
    pts = np.array(piece.find("Points/DataArray").text.split(), dtype=float).reshape(-1, 3)
    conn = None
    for arr in piece.find("Cells").findall("DataArray"):
        if arr.get("Name") == "connectivity":
            conn = np.array(arr.text.split(), dtype=np.int64).reshape(-1, 4)
    if conn is None:
        sys.exit(f"{path}: no connectivity array")
    return pts, conn


def volume(pts, tets):
    a, b, c, d = (pts[tets[:, i]] for i in range(4))
    return float(np.sum(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))) / 6.0)


def draw(ax, pts, tets, title, color):
    edges = set()
    for t in tets:
        for i in range(4):
            for j in range(i + 1, 4):
                edges.add((min(t[i], t[j]), max(t[i], t[j])))
    for i, j in edges:
        ax.plot([pts[i, 0], pts[j, 0]], [pts[i, 1], pts[j, 1]], color=color, lw=0.8)
    ax.set_title(title, fontsize=10)
    ax.set_aspect("equal")
    ax.grid(True, lw=0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def read_probe(path, column):
    t, u = [], []
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            t.append(float(row["time"]))
            u.append(float(row[column]))
    return np.array(t), np.array(u)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--corot", required=True, help="output folder of the co-rotational run")
    p.add_argument("--linear", required=True, help="output folder of the linear run")
    p.add_argument("--body", default="beam")
    p.add_argument("--probe", default="tip_uy", help="probes.csv column drawn over time")
    p.add_argument("--out", required=True, help="PNG to write")
    a = p.parse_args()

    runs = {}
    for key in ("corot", "linear"):
        series = read_pvd(os.path.join(getattr(a, key), a.body + ".pvd"))
        runs[key] = (read_vtu(series[0][1]), read_vtu(series[-1][1]), series[-1][0])
    (x0, tets), _, _ = runs["corot"]
    v0 = volume(x0, tets)
    vc = volume(runs["corot"][1][0], tets)
    vl = volume(runs["linear"][1][0], tets)

    fig = plt.figure(figsize=(13, 8))
    gs = fig.add_gridspec(2, 3, height_ratios=[1.3, 1])
    axes = [fig.add_subplot(gs[0, i]) for i in range(3)]
    draw(axes[0], x0, tets, "(a) initial configuration", "0.3")
    draw(axes[1], runs["corot"][1][0], tets,
         f"(b) co-rotational, t = {runs['corot'][2]:.2f} s\nvolume change {100 * (vc / v0 - 1):+.1f} %", "tab:blue")
    draw(axes[2], runs["linear"][1][0], tets,
         f"(c) linear, t = {runs['linear'][2]:.2f} s\nvolume change {100 * (vl / v0 - 1):+.1f} %", "tab:red")
    lo = np.min([ax.get_xlim()[0] for ax in axes] + [ax.get_ylim()[0] for ax in axes])
    hi = np.max([ax.get_xlim()[1] for ax in axes] + [ax.get_ylim()[1] for ax in axes])
    for ax in axes:  # one scale for all three shapes, as in the paper
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)

    ax = fig.add_subplot(gs[1, :])
    for key, color, label in (("corot", "tab:blue", "co-rotational"), ("linear", "tab:red", "linear")):
        t, u = read_probe(os.path.join(getattr(a, key), "probes.csv"), a.probe)
        ax.plot(t, u, color=color, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tip vertical displacement [m]")
    ax.set_title("(d) tip displacement over time (probes.csv of each run)", fontsize=10)
    ax.grid(True, lw=0.3)
    ax.legend()
    fig.suptitle("corofem: the paper's Fig. 8 beam (8 cells x 5 tetrahedra) under gravity, clamped at x = 0")
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    fig.savefig(a.out, dpi=110)
    print(f"initial volume {v0:.6g} m^3; co-rotational {100 * (vc / v0 - 1):+.2f} %; linear {100 * (vl / v0 - 1):+.2f} %")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
