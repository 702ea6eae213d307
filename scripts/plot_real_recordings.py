#!/usr/bin/env python3
"""Plots of the gap diagnosis on a ventilator recording (doc/gap_real_recordings.md).

Usage: plot_real_recordings.py GAP_REPORT_DIR OUT_PNG [--title TEXT] [--cause CAUSE_REPORT_DIR]

Draws the measured airway pressure of the report's first fit run against the nominal model
(dashed) and the calibrated model (solid), from GAP_REPORT_DIR/traces/*.csv (p_meas_pa,
p_nominal_pa, p_after_pa); with --cause, also the model with the named cause from that report's
traces. Flow below, in L/s.
"""
import argparse
import glob
import os

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

CMH2O = 98.0665
RHO = 1.204


def read(path):
    rows, names = [], None
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                continue
            if names is None:
                names = line.strip().split(",")
                continue
            rows.append([float(x) if x and x[0] in "-0123456789." else np.nan for x in line.strip().split(",")])
    a = np.array(rows)
    return {n: a[:, i] for i, n in enumerate(names)}


def first_trace(report_dir):
    return sorted(glob.glob(os.path.join(report_dir, "traces", "*.csv")))[0]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("report")
    ap.add_argument("out")
    ap.add_argument("--title", default="")
    ap.add_argument("--cause")
    ap.add_argument("--cause-label", default="model + named cause")
    a = ap.parse_args()
    d = read(first_trace(a.report))
    fig, (ax, axq) = plt.subplots(2, 1, figsize=(8, 5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    t = d["t_s"]
    ax.plot(t, d["p_meas_pa"] / CMH2O, "k.", ms=2, label="recorded")
    ax.plot(t, d["p_nominal_pa"] / CMH2O, "--", color="tab:gray", label="nominal model (lung file)")
    ax.plot(t, d["p_after_pa"] / CMH2O, "-", color="tab:blue", label="calibrated model")
    if a.cause:
        c = read(first_trace(a.cause))
        ax.plot(c["t_s"], c["p_after_pa"] / CMH2O, "-", color="tab:red", lw=1, label=a.cause_label)
    ax.set_ylabel("airway pressure [cmH2O]")
    ax.legend(fontsize=8)
    ax.set_title(a.title, fontsize=10)
    axq.plot(t, d["mdot_in_kg_s"] / RHO * 1e3, color="tab:green")
    axq.set_ylabel("flow [L/s]")
    axq.set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(a.out, dpi=100)


if __name__ == "__main__":
    main()
