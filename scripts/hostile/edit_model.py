#!/usr/bin/env python3
"""Edits a COLMAP text model (cameras.txt, images.txt, points3D.txt) in place, for
hostile-input tests of the scene loader.

Usage: edit_model.py SPARSE_DIR EDIT
EDIT is Python run with `cameras` (list of [id, model, w, h, params...] as strings), `images`
(list of [header fields, points2D line]) and `points` (list of field lists) in scope.
Example: edit_model.py scene/sparse/0 'cameras[0][4] = "0"'
"""
import os
import sys


def lines(path):
    return [l.rstrip("\n") for l in open(path, encoding="latin-1") if not l.startswith("#")]


def main():
    d, edit = sys.argv[1], sys.argv[2]
    cameras = [l.split() for l in lines(os.path.join(d, "cameras.txt")) if l.strip()]
    raw = lines(os.path.join(d, "images.txt"))
    images = [[raw[i].split(" ", 9), raw[i + 1] if i + 1 < len(raw) else ""] for i in range(0, len(raw), 2) if raw[i].strip()]
    points = [l.split() for l in lines(os.path.join(d, "points3D.txt")) if l.strip()]
    exec(edit, {"cameras": cameras, "images": images, "points": points})
    with open(os.path.join(d, "cameras.txt"), "w", encoding="latin-1") as f:
        f.writelines(" ".join(c) + "\n" for c in cameras)
    with open(os.path.join(d, "images.txt"), "w", encoding="latin-1") as f:
        for head, obs in images:
            f.write(" ".join(head) + "\n" + obs + "\n")
    with open(os.path.join(d, "points3D.txt"), "w", encoding="latin-1") as f:
        f.writelines(" ".join(p) + "\n" for p in points)


if __name__ == "__main__":
    main()
