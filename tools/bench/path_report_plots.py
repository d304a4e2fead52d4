#!/usr/bin/python3
"""Plots of texstream-bench path (issue 8), from OUT/results.json and OUT/raw/<configuration>.csv.

  plots/fig6_<name>.png   seed 000 Fig. 6 for one configuration: frame latency and t_w over time (top), load
                          size s and mip bias b (middle), transfer rate in MB/s and mips/s (bottom)
  plots/error_over_time.png   PSNR against the reference frames over the path, cuts marked
  plots/mip_deficit.png   weighted mip deficit over the path (levels; frames.csv mip_deficit), cuts marked
  plots/pareto.png        run time against error: p95 and p99 frame latency vs time-integrated MSE, one point
                          per configuration, the Pareto front drawn through the non-dominated ones

usage: path_report_plots.py OUT
"""
import csv
import json
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")  # headless
import matplotlib.pyplot as plt  # noqa: E402

RATE_WINDOW_S = 0.10423  # seed 000 §4.2 sampling interval, as path_analysis.hpp


def read_frames(path):
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            rows.append({k: (float(v) if v != "" else math.nan) for k, v in r.items()})
    return rows


def rates(frames):
    """(time_s, mips/s, MB/s) per window of at least RATE_WINDOW_S wall time."""
    out, start, mips, byts = [], 0.0, 0.0, 0.0
    for f in frames:
        mips += f["mips"]
        byts += f["bytes"]
        span = f["wall_s"] - start
        if span >= RATE_WINDOW_S:
            out.append((f["time_s"], mips / span, byts / 1e6 / span))
            start, mips, byts = f["wall_s"], 0.0, 0.0
    return out


def fig6(frames, label, cuts, file):
    t = [f["time_s"] for f in frames]
    fig, (a, b, c) = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    a.plot(t, [f["latency_ms"] for f in frames], lw=0.8, label="frame latency")
    a.plot(t, [f["tw_ms"] for f in frames], lw=1.2, label="$t_w$")
    a.set_ylabel("ms")
    a.legend(loc="upper right")
    a.set_title(label)
    b.plot(t, [f["load_size_mb"] for f in frames], lw=1.0, color="tab:green", label="load size s")
    b.set_ylabel("s (MB)")
    b.set_yscale("log")
    b2 = b.twinx()
    b2.plot(t, [f["mip_bias"] for f in frames], lw=1.0, color="tab:red", label="mip bias b")
    b2.set_ylabel("b (levels)")
    b.legend(loc="upper left")
    b2.legend(loc="upper right")
    r = rates(frames)
    c.plot([x[0] for x in r], [x[2] for x in r], lw=1.0, label="MB/s")
    c.set_ylabel("MB/s")
    c2 = c.twinx()
    c2.plot([x[0] for x in r], [x[1] for x in r], lw=1.0, color="tab:purple", label="mips/s")
    c2.set_ylabel("mips/s")
    c.legend(loc="upper left")
    c2.legend(loc="upper right")
    c.set_xlabel("path time (s)")
    for ax in (a, b, c):
        for x in cuts:
            ax.axvline(x, color="grey", ls=":", lw=0.8)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)


def over_time(runs, frames, cuts, key, ylabel, ybottom, legend_loc, measured_only, file):
    """One frames.csv column over path time for the baseline-group and lock-step runs, cuts marked."""
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for r in runs:
        if (measured_only and not r["measured"]) or r["group"] not in ("baseline", "lockstep") \
                or r["name"] == "lockstep_b":
            continue
        fr = frames[r["name"]]
        if fr and key in fr[0]:  # older frames.csv files lack newer columns
            ax.plot([f["time_s"] for f in fr], [f[key] for f in fr], lw=1.0, label=r["label"])
    for x in cuts:
        ax.axvline(x, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("path time (s)")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=ybottom)
    ax.legend(fontsize=7, loc=legend_loc)
    fig.tight_layout()
    fig.savefig(file, dpi=110)
    plt.close(fig)


def main():
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = sys.argv[1]
    with open(os.path.join(out, "results.json")) as f:
        res = json.load(f)
    os.makedirs(os.path.join(out, "plots"), exist_ok=True)
    cuts = res.get("cuts_s", [])
    runs = [r for r in res["runs"] if not r["failure"] and os.path.exists(os.path.join(out, r["raw_csv"]))]
    frames = {r["name"]: read_frames(os.path.join(out, r["raw_csv"])) for r in runs}

    for name in ("ours", "baseline"):
        if name in frames:
            label = next(r["label"] for r in runs if r["name"] == name)
            fig6(frames[name], label, cuts, os.path.join(out, "plots", f"fig6_{name}.png"))

    over_time(runs, frames, cuts, "psnr_db", "PSNR against the reference (dB)", 10, "lower right", True,
              os.path.join(out, "plots", "error_over_time.png"))
    over_time(runs, frames, cuts, "mip_deficit", "weighted mip deficit (levels)", 0, "upper right", False,
              os.path.join(out, "plots", "mip_deficit.png"))

    # Run time against error, p95 and p99 frame latency: one point per configuration (ours, the seed's method,
    # the baseline, blocking loads, the α / β sweeps, repeats), the Pareto front through the non-dominated ones.
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.5))
    for ax, key, name in ((axes[0], "p95_latency_ms", "p95"), (axes[1], "p99_latency_ms", "p99")):
        pts = [(r[key], r["integrated_mse"], r["name"]) for r in runs
               if r["measured"] and r.get(key) is not None and r["integrated_mse"] is not None]
        for x, y, label in pts:
            ax.scatter([x], [max(y, 1e-3)])
            ax.annotate(label, (x, max(y, 1e-3)), fontsize=7, xytext=(4, 3), textcoords="offset points")
        # Pareto front: no other configuration is both faster and more accurate.
        front = sorted((p for p in pts if not any(q[0] <= p[0] and q[1] <= p[1] and q != p for q in pts)),
                       key=lambda p: p[0])
        if len(front) > 1:
            ax.plot([p[0] for p in front], [max(p[1], 1e-3) for p in front], "k--", lw=0.8, label="Pareto front")
            ax.legend(fontsize=8)
        ax.set_yscale("log")
        ax.set_xlabel(f"{name} frame latency (ms)")
        ax.set_ylabel("time-integrated MSE (MSE·s; 0 drawn at 1e-3)")
        ax.set_title(f"run time ({name}) against error (lower left is better)")
    fig.suptitle(f"{res.get('device', '?')}")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "plots", "pareto.png"), dpi=110)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
