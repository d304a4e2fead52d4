#!/usr/bin/env python3
"""Plots of texstream-bench storage (issue 4): storage_plots.py OUT_DIR.

Reads what the bench wrote to OUT_DIR and draws
  storage_fig12.png     seed 002 Fig. 12 redone: time-integrated image error (sum of MSE * dt over the camera
                        path) against link rate, log x axis (the unlimited link drawn right of the fastest
                        capped one), and the MSE over the path per link
  storage_timeline.png  cumulative MB delivered over time per link (phase 3, the server alone)
A missing input skips its plot with a note; a malformed one fails with its file and line.
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")  # no display on the bench machines
import matplotlib.pyplot as plt  # noqa: E402


def read_rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def number(row, key, path, line):
    try:
        return float(row[key]) if row[key] != "" else math.nan
    except (KeyError, ValueError) as e:
        raise SystemExit(f"{path}:{line}: column {key!r}: {e}")


def plot_fig12(out):
    summary = os.path.join(out, "storage_fig12.csv")
    frames = os.path.join(out, "storage_fig12_frames.csv")
    if not os.path.exists(summary) or not os.path.exists(frames):
        print(f"storage_plots: no {summary} or {frames}: Fig. 12 not drawn")
        return
    links = []
    for i, row in enumerate(read_rows(summary), start=2):
        if row.get("failure"):
            continue
        links.append((row["link"], number(row, "nominal_bytes_s", summary, i), number(row, "integrated_mse", summary, i)))
    if not links:
        print(f"storage_plots: {summary} has no successful link: Fig. 12 not drawn")
        return
    capped = [rate for _, rate, _ in links if rate > 0]
    unlimited_x = (max(capped) if capped else 1e6) * 10  # a position for "unlimited" on the log axis
    fig, (ax_err, ax_time) = plt.subplots(1, 2, figsize=(12, 4.5))
    xs = [rate if rate > 0 else unlimited_x for _, rate, _ in links]
    ys = [err for _, _, err in links]
    order = sorted(range(len(xs)), key=lambda k: xs[k])
    ax_err.plot([xs[k] for k in order], [ys[k] for k in order], "o-")
    for (name, _, err), x in zip(links, xs):
        ax_err.annotate(name, (x, err), textcoords="offset points", xytext=(4, 6), fontsize=8)
    ax_err.set_xscale("log")
    ax_err.set_xlabel("link rate (bytes/s; rightmost point: unlimited)")
    ax_err.set_ylabel("time-integrated MSE (MSE * s)")
    ax_err.set_title("Fig. 12: integrated image error vs link rate")
    ax_err.grid(True, which="both", alpha=0.3)

    series = {}
    for i, row in enumerate(read_rows(frames), start=2):
        series.setdefault(row["link"], ([], []))
        series[row["link"]][0].append(number(row, "time_s", frames, i))
        series[row["link"]][1].append(number(row, "mse", frames, i))
    for name, (t, mse) in series.items():
        ax_time.plot(t, mse, label=name)
    ax_time.set_xlabel("time along the camera path (s)")
    ax_time.set_ylabel("MSE against the reference frame")
    ax_time.set_title("image error over time per link")
    ax_time.legend(fontsize=8)
    ax_time.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "storage_fig12.png"), dpi=110)
    plt.close(fig)


def plot_timeline(out):
    path = os.path.join(out, "storage_timeline.csv")
    if not os.path.exists(path):
        print(f"storage_plots: no {path}: timeline not drawn")
        return
    series = {}
    for i, row in enumerate(read_rows(path), start=2):
        series.setdefault(row["link"], ([], []))
        series[row["link"]][0].append(number(row, "seconds", path, i))
        series[row["link"]][1].append(number(row, "bytes", path, i) / 1e6)
    if not series:
        print(f"storage_plots: {path} is empty: timeline not drawn")
        return
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, (t, mb) in series.items():
        ax.plot(t, mb, label=name, linestyle="--" if name.endswith("_emulated") else "-")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("cumulative MB delivered")
    ax.set_yscale("symlog", linthresh=0.01)
    ax.set_title("streaming the scene coarsest first, per link")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "storage_timeline.png"), dpi=110)
    plt.close(fig)


def main():
    if len(sys.argv) != 2:
        raise SystemExit("usage: storage_plots.py OUT_DIR")
    plot_fig12(sys.argv[1])
    plot_timeline(sys.argv[1])


if __name__ == "__main__":
    main()
