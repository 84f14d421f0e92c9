#!/usr/bin/python3
"""Drags a beam by a handle through corofem's C API from Python (ctypes, no build step) and plots
what its free tip does.

    /usr/bin/python3 samples/python/drag_tip.py --lib build/libcorofem_c.so --out out/python

A soft beam (0.8 m x 0.1 m x 0.1 m, E = 5e5 Pa), clamped at x = 0, hangs under gravity. At 60 Hz a
handle holding the cross-section at x = 0.4 m draws a circle of 8 cm radius in the y-z plane for
2 s, then lets go, and the beam swings for 1 s more. Writes OUT/drag_tip.png (the handle's path and
the tip's, over time and seen along the beam, and the beam's side view at a few frames) and
OUT/drag_tip.csv, and checks as it goes: the held nodes' centroid is on the handle's target to
1e-9 m every frame, and the tip follows (exit status 1 otherwise). Exit status 77 (a skip) where
this Python lacks numpy or matplotlib.

libcorofem_c.so is the shared library that exports corofem's C API (corofem/corofem.h): the
build makes it (target corofem_c) beside the static library.
"""
import argparse
import ctypes as C
import math
import os
import sys

try:
    import numpy as np
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError as e:  # the CTest test counts exit status 77 as skipped
    print(f"drag_tip.py: skipping: this Python ({sys.executable}) lacks numpy or matplotlib ({e}); "
          "on Debian: apt-get install python3-numpy python3-matplotlib")
    sys.exit(77)

SCENE = """{
  "name": "drag_tip",
  "bodies": [{
    "name": "beam",
    "mesh": {"box": {"min": [0, 0, 0], "max": [0.8, 0.1, 0.1], "cells": [16, 2, 2], "tets_per_cell": 6}},
    "material": {"youngs_modulus": 5e5, "poisson_ratio": 0.3, "density": 1000, "rayleigh_mass": 0.5},
    "fixed": [{"plane": {"point": [0, 0, 0], "normal": [1, 0, 0]}}],
    "loads": [{"type": "gravity", "vector": [0, -9.81, 0]}]
  }],
  "analysis": {"type": "dynamic", "integrator": "backward_euler", "time_step": 0.016666666666666666,
               "steps": 1, "newton_iterations": 2},
  "solver": {"tolerance": 1e-8, "max_iterations": 2000},
  "backend": "%s"
}"""

FPS = 60.0
HELD_SECONDS = 2.0
FREE_SECONDS = 1.0
RADIUS = 0.08  # m, of the handle's circle


class StepReport(C.Structure):
    """corofem_step_report"""
    _fields_ = [("step", C.c_int), ("time", C.c_double), ("newton_iterations", C.c_int),
                ("linear_iterations", C.c_int), ("residual", C.c_double), ("linear_residual", C.c_double),
                ("converged", C.c_int), ("wall_seconds", C.c_double)]


class CorofemError(RuntimeError):
    pass


class Corofem:
    """The few C API calls this sample makes, each checked: a failure raises with corofem's message."""

    def __init__(self, path):
        lib = C.CDLL(path)
        self.lib = lib
        P, I, D, S = C.c_void_p, C.c_int, C.c_double, C.c_size_t
        dp, up, sp, ip = C.POINTER(C.c_double), C.POINTER(C.c_uint32), C.POINTER(C.c_size_t), C.POINTER(C.c_int)
        signatures = {
            "corofem_scene_parse": [C.c_char_p, C.c_char_p, P, S, C.POINTER(P)],
            "corofem_scene_set_step_count": [P, I],
            "corofem_simulation_create": [P, P, C.POINTER(P)],
            "corofem_simulation_node_count": [P, I, sp],
            "corofem_simulation_read_rest_positions": [P, I, dp, S, sp],
            "corofem_simulation_read_positions": [P, I, dp, S, sp],
            "corofem_simulation_add_handle_nodes": [P, I, up, S, ip],
            "corofem_simulation_move_handle": [P, I, dp, dp],
            "corofem_simulation_remove_handle": [P, I],
            "corofem_simulation_step_dt": [P, D, C.POINTER(StepReport)],
            "corofem_simulation_backend_name": [P, C.c_char_p, S, sp],
        }
        for name, args in signatures.items():
            f = getattr(lib, name)
            f.argtypes = args
            f.restype = C.c_int
        for name in ("corofem_version", "corofem_last_error_message"):
            getattr(lib, name).restype = C.c_char_p
            getattr(lib, name).argtypes = []
        lib.corofem_status_name.restype = C.c_char_p
        lib.corofem_status_name.argtypes = [C.c_int]
        lib.corofem_scene_destroy.argtypes = [P]
        lib.corofem_scene_destroy.restype = None
        lib.corofem_simulation_destroy.argtypes = [P]
        lib.corofem_simulation_destroy.restype = None
        self.version = lib.corofem_version().decode()

    def __call__(self, name, *args):
        status = getattr(self.lib, name)(*args)
        if status != 0:
            raise CorofemError(f"{name}: {self.lib.corofem_status_name(status).decode()}: "
                               f"{self.lib.corofem_last_error_message().decode()}")


def vec(values):
    return (C.c_double * len(values))(*values)


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lib", default=os.path.join(here, "..", "..", "build", "libcorofem_c.so"),
                    help="libcorofem_c.so (default: build/libcorofem_c.so of this checkout)")
    ap.add_argument("--out", default="out/python", help="folder for drag_tip.png and drag_tip.csv")
    ap.add_argument("--backend", default="reference", choices=["reference", "opencl", "auto"],
                    help="the scene's backend (default: reference)")
    args = ap.parse_args()
    if not os.path.exists(args.lib):
        print(f"drag_tip.py: {args.lib} does not exist; build the target corofem_c "
              "(cmake --build build --target corofem_c) or give its path with --lib", file=sys.stderr)
        return 2
    cf = Corofem(args.lib)

    scene, sim = C.c_void_p(), C.c_void_p()
    cf("corofem_scene_parse", (SCENE % args.backend).encode(), b"", None, 0, C.byref(scene))
    try:
        cf("corofem_scene_set_step_count", scene, 0)  # open-ended: a frame loop
        cf("corofem_simulation_create", scene, None, C.byref(sim))
    finally:
        cf.lib.corofem_scene_destroy(scene)
    try:
        return run(cf, sim, args.out)
    finally:
        cf.lib.corofem_simulation_destroy(sim)


def run(cf, sim, out):
    count = C.c_size_t()
    cf("corofem_simulation_node_count", sim, 0, C.byref(count))
    n = count.value
    rest_c = (C.c_double * (3 * n))()
    cf("corofem_simulation_read_rest_positions", sim, 0, rest_c, 3 * n, None)
    rest = np.ctypeslib.as_array(rest_c).reshape(n, 3).copy()
    x_c = (C.c_double * (3 * n))()

    def positions():
        cf("corofem_simulation_read_positions", sim, 0, x_c, 3 * n, None)
        return np.ctypeslib.as_array(x_c).reshape(n, 3).copy()

    held = np.flatnonzero(np.abs(rest[:, 0] - 0.4) < 1e-9)
    tip = np.flatnonzero(np.abs(rest[:, 0] - 0.8) < 1e-9)
    nodes = (C.c_uint32 * len(held))(*held)
    handle = C.c_int()
    cf("corofem_simulation_add_handle_nodes", sim, 0, nodes, len(held), C.byref(handle))
    centre = rest[held].mean(axis=0)
    name = C.create_string_buffer(64)
    cf("corofem_simulation_backend_name", sim, name, 64, None)

    rows, shapes, worst = [], [], 0.0
    report = StepReport()
    frames_held, frames = int(HELD_SECONDS * FPS), int((HELD_SECONDS + FREE_SECONDS) * FPS)
    for frame in range(1, frames + 1):
        t = frame / FPS
        holding = frame <= frames_held
        if holding:
            phase = 2 * math.pi * t / HELD_SECONDS  # one turn, starting and ending at the rest centre
            target = centre + np.array([0.0, RADIUS * math.sin(phase), RADIUS * (1 - math.cos(phase))])
            cf("corofem_simulation_move_handle", sim, handle.value, vec(target), None)
        elif frame == frames_held + 1:
            cf("corofem_simulation_remove_handle", sim, handle.value)
        cf("corofem_simulation_step_dt", sim, 1.0 / FPS, C.byref(report))
        x = positions()
        if not np.all(np.isfinite(x)):
            print(f"drag_tip.py: frame {frame}: the positions are not finite", file=sys.stderr)
            return 1
        held_at = x[held].mean(axis=0)
        if holding:
            worst = max(worst, float(np.abs(held_at - target).max()))
        tip_at = x[tip].mean(axis=0)
        rows.append([t, *(target if holding else [math.nan] * 3), *held_at, *tip_at, report.linear_iterations])
        if frame % 30 == 0:
            shapes.append((t, x))

    data = np.array(rows)
    tip_rest = rest[tip].mean(axis=0)
    tip_swing = np.abs(data[:, 7:10] - tip_rest).max(axis=0)
    os.makedirs(out, exist_ok=True)
    header = "time_s,target_x,target_y,target_z,handle_x,handle_y,handle_z,tip_x,tip_y,tip_z,pcg_iterations"
    np.savetxt(os.path.join(out, "drag_tip.csv"), data, delimiter=",", header=header, comments="")
    plot(data, shapes, rest, os.path.join(out, "drag_tip.png"), name.value.decode())

    print(f"drag_tip.py: corofem {cf.version} ({name.value.decode()} backend), {frames} frames at {FPS:.0f} Hz: "
          f"the held nodes' centroid within {worst:.2e} m of the handle's target; the tip swung up to "
          f"{tip_swing[1]:.3f} m in y and {tip_swing[2]:.3f} m in z; {os.path.join(out, 'drag_tip.png')}")
    failed = []
    if worst > 1e-9:
        failed.append(f"the handle's nodes strayed {worst:.3g} m from its target (1e-9 m allowed)")
    if tip_swing[2] < 0.05:
        failed.append(f"the tip moved only {tip_swing[2]:.3g} m sideways while the handle drew a 16 cm circle")
    for f in failed:
        print(f"drag_tip.py: FAILED: {f}", file=sys.stderr)
    return 1 if failed else 0


def plot(data, shapes, rest, path, backend):
    t = data[:, 0]
    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.5))
    for k, axis, colour in ((2, "y", "C0"), (3, "z", "C1")):
        a.plot(t, data[:, k], "--", color=colour, lw=1, label=f"handle target {axis}")
        a.plot(t, data[:, 6 + k], color=colour, lw=1.5, label=f"tip {axis}")
    a.axvline(HELD_SECONDS, color="grey", lw=0.8)
    a.text(HELD_SECONDS, a.get_ylim()[1], " released", va="top", fontsize=8, color="grey")
    a.set_xlabel("time (s)")
    a.set_ylabel("position (m)")
    a.set_title("handle (x = 0.4 m) and tip (x = 0.8 m) over time")
    a.legend(fontsize=8)
    b.plot(data[:, 3], data[:, 2], "k--", lw=1, label="handle target")
    b.plot(data[:, 9], data[:, 8], lw=1.5, label="tip")
    b.set_xlabel("z (m)")
    b.set_ylabel("y (m)")
    b.set_aspect("equal", adjustable="datalim")
    b.set_title("seen along the beam")
    b.legend(fontsize=8)
    c.plot(rest[:, 0], rest[:, 1], ".", color="0.7", ms=3, label="rest")
    for (when, x), colour in zip(shapes, plt.cm.viridis(np.linspace(0, 1, len(shapes)))):
        c.plot(x[:, 0], x[:, 1], ".", color=colour, ms=3, label=f"t = {when:.1f} s")
    c.set_xlabel("x (m)")
    c.set_ylabel("y (m)")
    c.set_aspect("equal", adjustable="datalim")
    c.set_title("side view")
    c.legend(fontsize=7, ncol=2)
    fig.suptitle(f"corofem C API from Python (ctypes): a handle dragged along a circle, {backend} backend")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    try:
        sys.exit(main())
    except CorofemError as e:
        print(f"drag_tip.py: {e}", file=sys.stderr)
        sys.exit(1)
