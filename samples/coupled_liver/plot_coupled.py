#!/usr/bin/python3
"""Draws a coupled-mesh run (paper Sec. 5, Figs. 6-7): the coarse tetrahedral mesh that computes
the deformation next to the fine render surface it drives, at rest and deformed.

    /usr/bin/python3 samples/coupled_liver/plot_coupled.py --run out/coupled_liver --body liver \
        --out out/coupled_liver.png

Reads the run's own outputs: the first and last .vtu of <body>.pvd (tet mesh) and the first and
last OBJ in surface/ (the fine surface, written with "surface_obj": true).
"""
import argparse
import glob
import os
import xml.etree.ElementTree as ET

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection  # noqa: E402


def read_pvd(path):
    root = ET.parse(path).getroot()
    return [os.path.join(os.path.dirname(path), ds.get("file")) for ds in root.iter("DataSet")]


def read_vtu(path):
    piece = ET.parse(path).getroot().find("UnstructuredGrid/Piece")
    pts = np.array(piece.find("Points/DataArray").text.split(), dtype=float).reshape(-1, 3)
    for arr in piece.find("Cells").findall("DataArray"):
        if arr.get("Name") == "connectivity":
            return pts, np.array(arr.text.split(), dtype=np.int64).reshape(-1, 4)
    raise SystemExit(f"{path}: no connectivity")


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                f.extend([idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1))
    return np.array(v), np.array(f)


def boundary_faces(tets):
    faces = {}
    for t in tets:
        for a, b, c in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)):
            key = tuple(sorted((t[a], t[b], t[c])))
            faces[key] = faces.get(key, 0) + 1
    return np.array([k for k, n in faces.items() if n == 1])


LIGHT = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])


def draw(ax, pts, tris, title, base, edge, alpha):
    """Flat-shaded triangles (Lambert, one light); the scene's y-up shown as the page's up."""
    p = pts[:, [0, 2, 1]]
    tri = p[tris]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
    shade = 0.35 + 0.65 * np.abs(n @ LIGHT)
    colors = np.clip(np.outer(shade, matplotlib.colors.to_rgb(base)), 0, 1)
    coll = Poly3DCollection(tri, facecolors=np.c_[colors, np.full(len(tri), alpha)],
                            edgecolors=edge, linewidths=0.25)
    ax.add_collection3d(coll)
    ax.set_title(title, fontsize=10)


def draw_edges(ax, pts, tris, color):
    p = pts[:, [0, 2, 1]]
    segs = [(p[a], p[b]) for t in tris for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))]
    ax.add_collection3d(Line3DCollection(segs, colors=color, linewidths=0.3))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", required=True)
    ap.add_argument("--body", default="liver")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()

    vtus = read_pvd(os.path.join(a.run, a.body + ".pvd"))
    x0, tets = read_vtu(vtus[0])
    x1, _ = read_vtu(vtus[-1])
    objs = sorted(glob.glob(os.path.join(a.run, "surface", a.body + "_surface_*.obj")))
    s0, tris = read_obj(objs[0])
    s1, _ = read_obj(objs[-1])
    bnd = boundary_faces(tets)

    fig = plt.figure(figsize=(14, 5))
    panels = [
        (x0, bnd, f"(a) coarse FE mesh at rest\n{len(x0)} nodes, {len(tets)} tetrahedra", "#8fb3e0", "#2b4c7e", 0.6),
        (x1, bnd, "(b) coarse FE mesh, deformed (grey: rest)\ncomputes the deformation", "#8fb3e0", "#2b4c7e", 0.6),
        (s1, tris, f"(c) fine surface it drives, deformed\n{len(s0)} vertices, {len(tris)} triangles", "#e3a27a", "none", 1.0),
    ]
    allp = np.vstack([x0, x1, s1])[:, [0, 2, 1]]
    lo, hi = allp.min(0), allp.max(0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    for i, (pts, faces, title, face, edge, alpha) in enumerate(panels):
        ax = fig.add_subplot(1, 3, i + 1, projection="3d")
        draw(ax, pts, faces, title, face, edge, alpha)
        if i == 1:  # the rest shape, faint, for comparison
            draw_edges(ax, x0, bnd, "#bbbbbb")
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.view_init(elev=20, azim=-70)
        ax.set_xlabel("x")
        ax.set_ylabel("z")
        ax.set_zlabel("y")
    fig.suptitle("corofem coupled mesh (paper Sec. 5): SOFA's liver, 596 tetrahedra driving its 2,194-vertex smooth surface;\n"
                 "right lobe fixed, left tip dragged by a prescribed displacement, gravity", fontsize=11)
    fig.subplots_adjust(left=0.0, right=0.97, bottom=0.02, top=0.80, wspace=0.05)
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    fig.savefig(a.out, dpi=110)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
