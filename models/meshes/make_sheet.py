#!/usr/bin/env python3
"""Writes sheet.obj: a flat square sheet in the z = 0 plane, as a modelling
tool would export it (header comment, o/mtllib/usemtl/s lines, vt and vn
records, quad faces v/vt/vn), so that loading it exercises the OBJ reader's
triangulation and ignored keywords.

Vertex (i, j), i, j in [0, n), is OBJ vertex 1 + i + n*j (0-based node
i + n*j) at (i/(n-1) * size, j/(n-1) * size, 0). Nodes 0 and n-1 are the two
corners of the edge y = 0: pin them to hang the sheet from that edge. With the
default n = 8 that is `pinned: [0, 7]`, the example of DESIGN.md section 9.

Deterministic: the same arguments always write the same bytes.
Usage: make_sheet.py [--n 8] [--size 1.0] [--output sheet.obj]
"""

import argparse
import pathlib


def sheet_obj(n: int, size: float) -> str:
    if n < 2:
        raise ValueError("n must be at least 2")
    lines = [
        "# sheet.obj: flat square sheet, %d x %d vertices, %g m x %g m, z = 0" % (n, n, size, size),
        "# Written by models/meshes/make_sheet.py; regenerate instead of editing.",
        "# Pin nodes 0 and %d (0-based): the corners of the edge y = 0." % (n - 1),
        "mtllib sheet.mtl",
        "o Sheet",
    ]
    for j in range(n):
        for i in range(n):
            lines.append("v %.6f %.6f %.6f" % (size * i / (n - 1), size * j / (n - 1), 0.0))
    for j in range(n):
        for i in range(n):
            lines.append("vt %.6f %.6f" % (i / (n - 1), j / (n - 1)))
    lines.append("vn 0.000000 0.000000 1.000000")
    lines.append("usemtl Cloth")
    lines.append("s off")

    def corner(i: int, j: int) -> str:
        k = 1 + i + n * j  # OBJ indices are 1-based; vt shares the vertex numbering
        return "%d/%d/1" % (k, k)

    for j in range(n - 1):
        for i in range(n - 1):
            # Counter-clockwise seen from +z, so the normal is +z.
            quad = [corner(i, j), corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)]
            lines.append("f " + " ".join(quad))
    return "\n".join(lines) + "\n"


def main() -> None:
    here = pathlib.Path(__file__).resolve().parent
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=8, help="vertices per side")
    parser.add_argument("--size", type=float, default=1.0, help="side length in metres")
    parser.add_argument("--output", type=pathlib.Path, default=here / "sheet.obj")
    args = parser.parse_args()
    args.output.write_text(sheet_obj(args.n, args.size))


if __name__ == "__main__":
    main()
