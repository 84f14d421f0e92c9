#!/usr/bin/python3
"""Draws samples/interactive's run: four frames of the liver's deformed surface, the handle's target
against the grabbed lobe's centroid, and each frame's times; prints the median and 99th percentile
of the step, the surface update, the read-back and their sum per frame.

usage: plot_interactive.py RUN_DIR OUT.png
"""
import csv
import glob
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            p = line.split()
            if not p:
                continue
            if p[0] == "v":
                v.append([float(c) for c in p[1:4]])
            elif p[0] == "f":
                f.append([int(c.split("/")[0]) - 1 for c in p[1:4]])
    return np.array(v), np.array(f)


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    run, out = sys.argv[1], sys.argv[2]
    rows = list(csv.DictReader(open(os.path.join(run, "frames.csv"))))
    if not rows:
        sys.exit(f"plot_interactive.py: {run}/frames.csv has no frames")
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k != "status"}
    total = col["step_ms"] + col["surface_ms"] + col["readback_ms"]
    failed = sum(r["status"] != "ok" for r in rows)
    for name, v in (("step", col["step_ms"]), ("surface update", col["surface_ms"]),
                    ("read-back", col["readback_ms"]), ("frame (sum)", total)):
        print(f"{name:15s} median {np.median(v):7.3f} ms   p99 {np.percentile(v, 99):7.3f} ms")
    print(f"{len(rows)} frames, {failed} failed step(s)")

    frames = sorted(glob.glob(os.path.join(run, "frame_*.obj")))
    picks = [frames[int(i)] for i in np.linspace(0, len(frames) - 1, 4)] if len(frames) >= 4 else frames
    fig = plt.figure(figsize=(16, 8))
    for i, path in enumerate(picks):
        ax = fig.add_subplot(2, 4, i + 1, projection="3d")
        v, f = read_obj(path)
        ax.plot_trisurf(v[:, 0], v[:, 2], v[:, 1], triangles=f, color="#c66", linewidth=0, alpha=0.9)
        ax.set_title(os.path.basename(path))
        ax.set_xlim(-6, 2), ax.set_ylim(-2, 3), ax.set_zlim(0, 7)
        ax.view_init(20, -70)
    ax = fig.add_subplot(2, 4, (5, 6))
    for k, c in (("x", "C0"), ("y", "C1"), ("z", "C2")):
        ax.plot(col["time_s"], col["target_" + k], c + "--", label="target " + k)
        ax.plot(col["time_s"], col["grab_" + k], c, label="lobe " + k)
    ax.set_xlabel("t (s)"), ax.set_ylabel("position"), ax.legend(ncol=3, fontsize=8)
    ax.set_title("handle target (dashed) and grabbed lobe")
    ax = fig.add_subplot(2, 4, (7, 8))
    ax.plot(col["time_s"], col["step_ms"], label="step")
    ax.plot(col["time_s"], col["surface_ms"] + col["readback_ms"], label="surface + read-back")
    ax.set_xlabel("t (s)"), ax.set_ylabel("ms"), ax.legend()
    ax.set_title(f"per frame: median {np.median(total):.2f} ms, p99 {np.percentile(total, 99):.2f} ms")
    fig.tight_layout()
    fig.savefig(out, dpi=80)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
