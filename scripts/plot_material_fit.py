#!/usr/bin/env python3
"""Plot measured vs fitted engineering stress of a Yeoh fit (written by fit_material).

Usage: plot_material_fit.py FIT.csv OUT.png [title]
FIT.csv columns: stretch, stress_pa_measured, stress_pa_fitted.
Panels: stress [MPa] vs stretch on a linear and on a log axis (the log axis shows the
small-stretch region), and the residual relative to the measured stress [%].
"""
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def main():
    if len(sys.argv) not in (3, 4) or sys.argv[1] in ("-h", "--help"):
        sys.stderr.write(__doc__)
        return 2
    fit_csv, out_png = sys.argv[1], sys.argv[2]
    title = sys.argv[3] if len(sys.argv) == 4 else "Yeoh fit"
    d = np.genfromtxt(fit_csv, delimiter=",", names=True)
    order = np.argsort(d["stretch"])
    stretch = d["stretch"][order]
    measured = d["stress_pa_measured"][order] * 1e-6
    fitted = d["stress_pa_fitted"][order] * 1e-6

    fig = plt.figure(figsize=(9, 6.5))
    grid = fig.add_gridspec(2, 2, height_ratios=(2.2, 1))
    ax_lin = fig.add_subplot(grid[0, 0])
    ax_log = fig.add_subplot(grid[0, 1])
    ax_res = fig.add_subplot(grid[1, :])
    for ax, log in ((ax_lin, False), (ax_log, True)):
        keep = measured > 0 if log else np.ones_like(measured, dtype=bool)
        ax.plot(stretch[keep], measured[keep], "o", ms=3.5, mfc="none", label="measured")
        keep_fit = fitted > 0 if log else np.ones_like(fitted, dtype=bool)
        ax.plot(stretch[keep_fit], fitted[keep_fit], "-", lw=1.6, label="Yeoh fit")
        if log:
            ax.set_yscale("log")
        ax.set_xlabel("stretch $\\lambda$ [-]")
        ax.set_ylabel("engineering stress [MPa]")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    nonzero = np.abs(measured) > 1e-6 * np.abs(measured).max()
    ax_res.plot(stretch[nonzero], 100.0 * (measured[nonzero] - fitted[nonzero]) / measured[nonzero],
                "o-", ms=3, lw=0.8)
    ax_res.axhline(0.0, color="k", lw=0.8)
    ax_res.set_xlabel("stretch $\\lambda$ [-]")
    ax_res.set_ylabel("(measured - fit) / measured [%]")
    ax_res.grid(True, alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
