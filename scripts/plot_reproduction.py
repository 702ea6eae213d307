#!/usr/bin/env python3
"""Plots of paper_reproduction's output directory: h(t), p(t), inflow(t) and h(p) with the
paper's eq. 24 (x read as bar) beside ours. Usage: plot_reproduction.py DIR"""
import glob
import json
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

PAPER_QUARTIC_MM_VS_BAR = [-4.603e5, 4.099e5, -1.349e5, 1.955e4, -9.741e2]


def load_csv(path):
    """A CSV with leading '#' comment lines and a header row, as a numpy record array."""
    with open(path) as f:
        lines = [line for line in f if not line.startswith("#")]
    return np.genfromtxt(lines, delimiter=",", names=True)


def main(out_dir):
    summary = json.load(open(os.path.join(out_dir, "summary.json")))
    traces = []
    for entry in summary["loads"]:
        path = os.path.join(out_dir, "inflation_load_%.1fN.csv" % entry["load_n"])
        traces.append((entry, load_csv(path)))

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    for entry, d in traces:
        label = "%.1f N (valve %.0f kPa)" % (entry["load_n"], entry["valve_pressure_pa"] / 1e3)
        axes[0].plot(d["t_s"], d["h_m"] * 1e3, label=label)
        axes[1].plot(d["t_s"], d["p_gauge_pa"] / 1e3, label=label)
        axes[2].plot(d["t_s"], d["inflow_kg_s"] * 1e3, label=label)
    axes[0].set(xlabel="time [s]", ylabel="plate height h [mm]", title="height during inflation")
    axes[1].set(xlabel="time [s]", ylabel="gauge pressure p [kPa]", title="internal pressure")
    axes[2].set(xlabel="time [s]", ylabel="inflow [g/s]", title="inflow (%s)" % summary["inflow_mode"])
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "h_p_vs_time.png"), dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for entry, d in traces:
        rising = d["t_s"] <= 5.5 + 1e-9
        ax.plot(d["p_gauge_pa"][rising] / 1e3, d["h_m"][rising] * 1e3, label="model, %.1f N" % entry["load_n"])
    char = os.path.join(out_dir, "characteristic.csv")
    if os.path.exists(char):
        c = load_csv(char)
        ax.plot(c["p_gauge_pa"] / 1e3, c["h_m_load_106N"] * 1e3, "k:", lw=1,
                label="model quasi-static, 10.6 N")
    x_bar = np.linspace(0.10, 0.28, 100)
    ax.plot(x_bar * 100, np.polyval(PAPER_QUARTIC_MM_VS_BAR, x_bar), "k--", lw=2,
            label="paper eq. 24 (x read as bar), 10.4 N")
    ax.set(xlabel="gauge pressure p [kPa]", ylabel="plate height h [mm]",
           title="h(p) during inflation; eq. 24 RMS (loaded, 10-28 kPa) = %s mm"
           % ("%.1f" % summary["eq24_rms_mm"] if summary["eq24_rms_mm"] is not None else "n/a"))
    ax.set_xlim(0, 30)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, "h_vs_p.png"), dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
