#!/usr/bin/env python3
"""Figures and figures-of-merit of doc/cell_geometry.md from the CSVs in doc/fe/geometry.

usage: /usr/bin/python3 scripts/plot_cell_geometry.py [doc/fe/geometry]
Prints the eq. 24 RMS (x read as bar, 14-28 kPa, 10.6 N) of each reading's FE h(p), the
transients' figures, and the fold-table cells' agreement with the FE (within 3 mm); writes
cell_geometry_hp.png, cell_geometry_transient.png and fold_check_<geometry>.png beside the CSVs.
"""
import glob
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from plot_fe import eq24_mm, rows  # noqa: E402  (the same paper curve and CSV reader)

READINGS = {"pillows_n12": "flat pillows", "gusseted_g27_n12": "gusseted, g = 27 mm"}
LOADS = [0.6, 10.6, 15.6, 20.6]


def rising(d, tag, load):
    """The FE's rising h(p) of one reading and load: (p [Pa], h [mm]), converged states only."""
    path = os.path.join(d, f"hp_{tag}_load_{load:g}N_updown.csv")
    if not os.path.exists(path):  # a rising-only run (fe_airbag hp without --and-back)
        path = os.path.join(d, f"hp_{tag}_load_{load:g}N.csv")
    rs = rows(path)
    top = int(np.argmax([float(r["p_gauge_pa"]) for r in rs]))
    rs = [r for r in rs[: top + 1] if r["converged"] == "1"]
    return np.array([float(r["p_gauge_pa"]) for r in rs]), np.array([float(r["h_m"]) * 1e3 for r in rs])


def eq24_rms(p, h):
    grid = np.linspace(14e3, 28e3, 15)
    return float(np.sqrt(np.mean((np.interp(grid, p, h) - eq24_mm(grid)) ** 2)))


def hp_table(d):
    """Markdown rows: each reading's rising h(p) at the FE state nearest 10, 15, 20 and 28 kPa."""
    print("| reading | load [N] | ~10 kPa | ~15 kPa | ~20 kPa | ~28 kPa |")
    print("|---|---|---|---|---|---|")
    for tag, name in READINGS.items():
        for load in LOADS + [40.0]:
            try:
                p, h = rising(d, tag, load)
            except FileNotFoundError:
                continue
            cells = []
            for target in (10e3, 15e3, 20e3, 28e3):
                k = int(np.argmin(np.abs(p - target)))
                cells.append(f"{h[k]:.1f} ({p[k] / 1e3:.1f})")
            print(f"| {name} | {load:g} | " + " | ".join(cells) + " |")
    ps = np.array([10e3, 15e3, 20e3, 28e3])
    print("| paper eq. 24 (x in bar) | 10.4 | " + " | ".join(f"{x:.1f}" for x in eq24_mm(ps)) + " |")


def hp_figure(d):
    hp_table(d)
    fig, ax = plt.subplots(figsize=(8, 5))
    for (tag, name), style in zip(READINGS.items(), ("-", "--")):
        for load, colour in zip(LOADS, ("C0", "C1", "C2", "C3")):
            p, h = rising(d, tag, load)
            ax.plot(p / 1e3, h, style, color=colour, marker=".", label=f"{name}, {load:g} N")
        p, h = rising(d, tag, 10.6)
        print(f"{name}: eq. 24 RMS over 14-28 kPa under 10.6 N {eq24_rms(p, h):.1f} mm; "
              f"unloaded at 20 kPa {np.interp(20e3, *rising(d, tag, 0.6)):.1f} mm, "
              f"10.6 N {np.interp(20e3, p, h):.1f} mm")
    ps = np.linspace(10e3, 28e3, 50)
    ax.plot(ps / 1e3, eq24_mm(ps), "k-", lw=2.5, label="paper eq. 24 (x in bar), 10.4 N")
    ax.axhline(150, color="grey", ls=":", label="paper: ~150 mm unloaded")
    ax.set_xlabel("gauge pressure [kPa]")
    ax.set_ylabel("plate height [mm]")
    ax.set_title("FE h(p), pressure rising: the two readings of the bag")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "cell_geometry_hp.png"), dpi=110)


def transient_figure(d):
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for path in sorted(glob.glob(os.path.join(d, "transient_*.csv"))):
        rs = rows(path)
        t = np.array([float(r["t_s"]) for r in rs])
        h = np.array([float(r["h_m"]) * 1e3 for r in rs])
        p = np.array([float(r["p_gauge_pa"]) / 1e3 for r in rs])
        name = os.path.basename(path)[len("transient_"):-len(".csv")]
        ax[0].plot(t, h, label=name)
        ax[1].plot(t, p, label=name)
        print(f"transient {name}: h(5.5 s) {np.interp(5.5, t, h):.1f} mm, p(5.5 s) {np.interp(5.5, t, p):.2f} kPa, "
              f"peak p {p.max():.2f} kPa at {t[p.argmax()]:.2f} s, largest dip {largest_dip(t, p):.2f} kPa")
    ax[0].plot([5.5], [150], "k*", ms=12, label="paper: ~150 mm at 5.5 s")
    ax[0].set_ylabel("plate height [mm]")
    ax[1].set_ylabel("gauge pressure [kPa]")
    for a in ax:
        a.set_xlabel("time [s]")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle("Unloaded 5.5 s inflation, paper-shaped inflow (peak at 1 s)")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "cell_geometry_transient.png"), dpi=110)


def largest_dip(t, p):
    """Largest fall of the pressure below its running maximum while the inflow lasts [kPa]."""
    inflow = t < 5.5
    return float(np.max(np.maximum.accumulate(p[inflow]) - p[inflow]))


def fold_figures(d):
    for path in sorted(glob.glob(os.path.join(d, "fold_check_*.csv"))):
        rs = rows(path)
        loads = sorted({float(r["load_n"]) for r in rs})
        fig, ax = plt.subplots(figsize=(8, 5))
        ok = 0
        for k, load in enumerate(loads):
            sub = [r for r in rs if float(r["load_n"]) == load]
            for direction, style in (("up", "-"), ("down", "--")):
                s = [r for r in sub if r["direction"] == direction]
                p = [float(r["p_gauge_pa"]) / 1e3 for r in s]
                ax.plot(p, [float(r["h_fe_m"]) * 1e3 for r in s], style, color=f"C{k}", alpha=0.5,
                        label=f"FE {load:g} N" if direction == "up" else None)
                ax.plot(p, [float(r["h_cell_m"]) * 1e3 for r in s], "o" if direction == "up" else "x",
                        color=f"C{k}", ms=3)
            ok += sum(abs(float(r["h_cell_m"]) - float(r["h_fe_m"])) <= 3e-3 for r in sub)
        tag = os.path.basename(path)[len("fold_check_"):-len(".csv")]
        print(f"fold table {tag}: {ok} of {len(rs)} states within 3 mm ({100.0 * ok / len(rs):.1f} %)")
        ax.set_title(f"fold-table cell (o rising, x falling) vs FE (lines), {tag}")
        ax.set_xlabel("gauge pressure [kPa]")
        ax.set_ylabel("plate height [mm]")
        ax.legend(fontsize=7, ncol=2)
        ax.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(d, f"fold_check_{tag}.png"), dpi=110)


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "doc/fe/geometry"
    hp_figure(d)
    transient_figure(d)
    fold_figures(d)


if __name__ == "__main__":
    main()
