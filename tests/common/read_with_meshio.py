#!/usr/bin/env python3
"""Reads a mesh file with meshio and writes what it found as JSON, for the C++ tests
(tests/common/meshio_reader.hpp): an independent reader of corofem's outputs.

usage: read_with_meshio.py MESH OUT.json

JSON: {"points": {"dtype", "shape", "values"}, "cells": [{"type", "values"}],
       "point_data": {name: {"dtype", "shape", "values"}}, "cell_data": {name: [{"dtype", "shape", "values"}]}}
Values are flattened in C order; floats print as the shortest decimal that reads back exactly (repr),
so the C++ side compares them bit for bit.
"""
import json
import sys

import meshio


def array(a):
    return {"dtype": str(a.dtype), "shape": list(a.shape), "values": a.reshape(-1).tolist()}


def main():
    mesh = meshio.read(sys.argv[1])
    out = {
        "points": array(mesh.points),
        "cells": [{"type": block.type, "values": block.data.reshape(-1).tolist()} for block in mesh.cells],
        "point_data": {name: array(a) for name, a in mesh.point_data.items()},
        "cell_data": {name: [array(a) for a in blocks] for name, blocks in mesh.cell_data.items()},
    }
    with open(sys.argv[2], "w") as f:
        json.dump(out, f, allow_nan=False)


if __name__ == "__main__":
    main()
