#!/usr/bin/env python3
"""Plots cnc_plan's setpoint CSV: position, velocity, acceleration and jerk of each axis over time,
with the limits drawn as dashed lines.

usage: plot_plan.py CSV PNG VMAX_X,Y,Z AMAX_X,Y,Z JMAX_X,Y,Z   (mm/s, mm/s^2, mm/s^3)
"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    path, png = sys.argv[1], sys.argv[2]
    limits = [[float(x) for x in arg.split(",")] for arg in sys.argv[3:6]]
    with open(path) as f:
        rows = list(csv.DictReader(f))
    t = [float(r["t_s"]) for r in rows]
    quantities = [("position", "mm", "{}_mm", None), ("velocity", "mm/s", "v{}_mm_s", limits[0]),
                  ("acceleration", "mm/s²", "a{}_mm_s2", limits[1]), ("jerk", "mm/s³", "j{}_mm_s3", limits[2])]
    fig, axes = plt.subplots(4, 3, figsize=(15, 11), sharex=True)
    for row, (name, unit, column, limit) in enumerate(quantities):
        for col, axis in enumerate("xyz"):
            ax = axes[row][col]
            ax.plot(t, [float(r[column.format(axis)]) for r in rows], linewidth=0.8)
            if limit is not None:
                ax.axhline(limit[col], color="red", linestyle="--", linewidth=0.8)
                ax.axhline(-limit[col], color="red", linestyle="--", linewidth=0.8)
            ax.set_title(f"{axis.upper()} {name}")
            ax.set_ylabel(unit)
            if row == 3:
                ax.set_xlabel("s")
    fig.tight_layout()
    fig.savefig(png, dpi=80)


if __name__ == "__main__":
    main()
