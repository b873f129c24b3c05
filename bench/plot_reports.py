#!/usr/bin/env python3
"""Draws the report plots from the CSV files that `stiffsim bench` writes.

    python3 bench/plot_reports.py DIR

DIR/precision.csv -> DIR/precision_<scene>.png (error against wall time, log-log,
one line per method and mode); DIR/scaling.csv -> DIR/scaling.png (time per step
against DOFs, one line per family and method). Files that are absent are skipped.
"""
import csv
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def slug(text):
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")


def precision(directory):
    path = os.path.join(directory, "precision.csv")
    if not os.path.exists(path):
        return []
    rows = read(path)
    written = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        fig, ax = plt.subplots(figsize=(7, 5))
        series = {}
        for r in rows:
            if r["scene"] != scene or r["finished"] != "1":
                continue
            error, wall = float(r["error"]), float(r["wall_seconds"])
            if not (error > 0 and wall > 0):
                continue
            label = r["method"] + (" (fixed h)" if r["mode"] == "fixed" else "")
            series.setdefault(label, []).append((wall, error))  # CSV order: accuracy tightening
        for label, points in sorted(series.items()):
            ax.loglog([p[0] for p in points], [p[1] for p in points], "o-", label=label, markersize=4)
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("max position error (m or rad)")
        ax.set_title("work-precision: " + scene)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        out = os.path.join(directory, "precision_" + slug(scene) + ".png")
        fig.tight_layout()
        fig.savefig(out, dpi=110)
        plt.close(fig)
        written.append(out)
    return written


def scaling(directory):
    path = os.path.join(directory, "scaling.csv")
    if not os.path.exists(path):
        return []
    rows = [r for r in read(path) if r["finished"] == "1"]
    fig, ax = plt.subplots(figsize=(7, 5))
    series = {}
    for r in rows:
        series.setdefault(r["family"] + ", " + r["method"], []).append(
            (int(r["dofs"]), float(r["ms_per_step"])))
    for label, points in sorted(series.items()):
        points.sort()
        style = "o-" if label.endswith("vie") else "s--"
        ax.loglog([p[0] for p in points], [p[1] for p in points], style, label=label, markersize=4)
    ax.set_xlabel("velocity DOFs")
    ax.set_ylabel("time per step (ms)")
    ax.set_title("scaling: fixed steps, time per step after the first")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    out = os.path.join(directory, "scaling.png")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return [out]


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: plot_reports.py DIR")
    for out in precision(sys.argv[1]) + scaling(sys.argv[1]):
        print("wrote", out)


if __name__ == "__main__":
    main()
