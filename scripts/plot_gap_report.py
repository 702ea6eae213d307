#!/usr/bin/env python3
"""Figures of a sim-to-real gap diagnosis report directory (report.json + traces/*.csv).

Usage: plot_gap_report.py DIR

Writes into DIR:
  traces.png             measured vs simulated (nominal model / model with the diagnosed effect)
  residual_by_phase.png  where the gap lives (localization shares) and RMS residual per phase
  hp_loops.png           height vs pressure loops per run
  cause_<effect>.png     per named cause: measured, the nominal model, the model with that cause alone
"""
import csv
import glob
import json
import os
import sys

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

PHASES = ["deploy", "pressurize", "hold", "vent", "landed"]
PHASE_COLORS = {"deploy": "tab:purple", "pressurize": "tab:orange", "hold": "tab:green",
                "vent": "tab:blue", "landed": "tab:gray"}
MAX_RUNS = 8
COLUMNS = ["t_s", "mdot_in_kg_s", "p_meas_pa", "h_meas_m", "p_nominal_pa", "h_nominal_m",
           "p_after_pa", "h_after_m"]
DPI = 110


def fail(msg):
    """Print an error to stderr and exit with code 1."""
    sys.stderr.write("plot_gap_report: error: %s\n" % msg)
    sys.exit(1)


def fmt(x, spec="%.2f"):
    """Format a number that may be null (None) in the JSON."""
    return "n/a" if x is None else spec % x


def load_report(out_dir):
    """report.json as a dict, with the keys this script relies on checked."""
    path = os.path.join(out_dir, "report.json")
    if not os.path.isfile(path):
        fail("%s not found" % path)
    try:
        with open(path) as f:
            rep = json.load(f)
    except (OSError, ValueError) as e:
        fail("cannot parse %s: %s" % (path, e))
    if not isinstance(rep, dict):
        fail("%s: top level is not a JSON object" % path)
    for key, kind in (("localization", list), ("verdict", dict), ("shrinkage", dict)):
        if not isinstance(rep.get(key), kind):
            fail("%s: key '%s' missing or not a JSON %s" % (path, key,
                                                            "array" if kind is list else "object"))
    return rep


def load_trace(path):
    """One trace CSV: ({'run', 'role', 'load_n', ...} from '#' lines, {column: array}, phases)."""
    meta, rows, header = {}, [], None
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line:
                continue
            if line.startswith("#"):  # "# key: value"; unknown keys are kept but unused
                key, _, value = line[1:].partition(":")
                meta[key.strip()] = value.strip()
            elif header is None:
                header = next(csv.reader([line]))
            else:
                rows.append(next(csv.reader([line])))
    if header is None:
        fail("%s: no header line" % path)
    missing = [c for c in COLUMNS + ["phase"] if c not in header]
    if missing:
        fail("%s: missing column(s) %s" % (path, ", ".join(missing)))
    if not rows:
        fail("%s: no data rows" % path)
    idx = {c: header.index(c) for c in header}

    def num(s):  # empty field -> NaN
        return float(s) if s.strip() else np.nan
    # Each named cause alone: p_with_<cause>_pa, h_with_<cause>_m.
    causes = [c[len("p_with_"):-len("_pa")] for c in header
              if c.startswith("p_with_") and c.endswith("_pa") and "h_with_%s_m" % c[7:-3] in header]
    columns = COLUMNS + ["p_with_%s_pa" % c for c in causes] + ["h_with_%s_m" % c for c in causes]
    try:
        data = {c: np.array([num(r[idx[c]]) for r in rows]) for c in columns}
        phases = np.array([r[idx["phase"]].strip() for r in rows], dtype=str)
    except (ValueError, IndexError) as e:
        fail("%s: bad data row: %s" % (path, e))
    meta.setdefault("run", os.path.basename(path))
    meta["causes"] = causes
    return meta, data, phases


def load_traces(out_dir, rep):
    """All traces, sorted withheld first then by run name."""
    paths = sorted(glob.glob(os.path.join(out_dir, "traces", "*.csv")))
    if not paths:
        fail("no trace files in %s" % os.path.join(out_dir, "traces"))
    withheld = set((rep.get("runs") or {}).get("withheld") or [])
    traces = []
    for p in paths:
        meta, data, phases = load_trace(p)
        if "role" not in meta:  # fall back to the run lists in report.json
            meta["role"] = "withheld" if meta["run"] in withheld else "fit"
        traces.append((meta, data, phases))
    traces.sort(key=lambda t: (t[0]["role"] != "withheld", t[0]["run"]))
    return traces


def run_title(meta):
    """Subplot title: run name, role and load."""
    load = meta.get("load_n")
    return "%s (%s%s)" % (meta["run"], meta["role"], ", %s N" % load if load else "")


def verdict_text(rep):
    """One line: what the diagnosis concluded and how much the withheld error shrank."""
    v, s = rep.get("verdict") or {}, rep.get("shrinkage") or {}
    status = v.get("status", "none")
    if status == "explained":
        head = "explained by " + " + ".join(v.get("effects") or ["?"])
    elif status == "unexplained":
        head = "gap unexplained by the candidate effects"
    else:
        head = "no significant gap"
    return "verdict: %s — withheld nrmse %s → %s" % (
        head, fmt(s.get("withheld_nrmse_before"), "%.3g"), fmt(s.get("withheld_nrmse_after"), "%.3g"))


def after_label(rep):
    """Legend label of the 'after' model: the named effect(s), or a note that it equals nominal."""
    v = rep.get("verdict") or {}
    if v.get("status") == "explained" and v.get("effects"):
        return "after: model + " + " + ".join(v["effects"])
    return "after: = nominal (no effect named)"


def shade_phases(ax, t, phases):
    """Lightly shade each contiguous phase segment of a trace."""
    if len(t) == 0:
        return
    start = 0
    for i in range(1, len(t) + 1):
        if i == len(t) or phases[i] != phases[start]:
            ax.axvspan(t[start], t[i - 1], color=PHASE_COLORS.get(phases[start], "white"),
                       alpha=0.10, lw=0)
            start = i


def plot_trace_rows(out_dir, file_name, runs, curves, title):
    """Pressure and height vs time, one row per run, phases shaded: `curves` are
    (column pattern with %s for p/h and the unit suffix, plot kwargs) drawn in that order."""
    fig, axes = plt.subplots(len(runs), 2, figsize=(13, 2.6 * len(runs) + 1.0), squeeze=False)
    for row, (meta, d, ph) in enumerate(runs):
        t = d["t_s"]
        for col, (sig, sfx, scale, unit, name) in enumerate(
                [("p", "pa", 1e-3, "kPa", "pressure"), ("h", "m", 1e3, "mm", "height")]):
            ax = axes[row, col]
            shade_phases(ax, t, ph)
            for column, style in curves:
                ax.plot(t, d[column % (sig, sfx)] * scale, **style)
            ax.set(ylabel="%s [%s]" % (name, unit), title="%s — %s" % (name, run_title(meta)))
            ax.grid(alpha=0.3)
            if row == len(runs) - 1:
                ax.set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8, loc="best")
    shading = [Patch(color=PHASE_COLORS[p], alpha=0.25, label=p) for p in PHASES]
    fig.legend(handles=shading, loc="upper right", ncol=5, fontsize=8, title="phase shading",
               title_fontsize=8)
    fig.suptitle(title, x=0.02, ha="left", fontsize=12)
    fig.tight_layout()
    fig.subplots_adjust(top=1 - 0.95 / fig.get_figheight())  # room for suptitle + shading legend
    path = os.path.join(out_dir, file_name)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


MEASURED = ("%s_meas_%s", dict(color="0.1", lw=0.7, zorder=3, label="measured"))


def plot_traces(out_dir, rep, runs):
    """traces.png: pressure and height vs time, measured / nominal / after, per run."""
    return plot_trace_rows(out_dir, "traces.png", runs, [
        MEASURED,
        ("%s_nominal_%s", dict(ls="--", color="tab:red", lw=1.2, zorder=2,
                               label="before: nominal model")),
        ("%s_after_%s", dict(color="tab:blue", lw=1.8, alpha=0.8, zorder=1,
                             label=after_label(rep)))],
        verdict_text(rep))


def plot_cause(out_dir, rep, runs, cause):
    """cause_<cause>.png: measured / nominal / the model with that cause alone, per run."""
    return plot_trace_rows(out_dir, "cause_%s.png" % cause, runs, [
        MEASURED,
        ("%s_nominal_%s", dict(ls="--", color="tab:red", lw=1.2, zorder=2, label="model")),
        ("%%s_with_%s_%%s" % cause, dict(color="tab:green", lw=1.8, alpha=0.8, zorder=1,
                                         label="model + " + cause))],
        "data, model and model + %s" % cause)


def rms(x):
    """RMS over the finite values, NaN if none."""
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x ** 2))) if len(x) else np.nan


def plot_residuals(out_dir, rep, traces):
    """residual_by_phase.png: localization shares and RMS residual per phase (all runs pooled)."""
    fig = plt.figure(figsize=(14, 6))
    gs = fig.add_gridspec(2, 2, width_ratios=(1, 1.2))
    ax_loc = fig.add_subplot(gs[:, 0])
    # Left: the largest localization shares, biggest on top.
    loc = [e for e in rep.get("localization") or [] if e.get("share") is not None]
    loc = sorted(loc, key=lambda e: -e["share"])[:10][::-1]
    labels = ["%s · %s · %s" % (e.get("signal") or "?", e.get("phase") or "?",
                                "%.1f N" % e["load_n"] if e.get("load_n") is not None else "all loads")
              for e in loc]
    shares = [100.0 * e["share"] for e in loc]
    ax_loc.barh(range(len(loc)), shares, color="tab:purple")
    ax_loc.set_yticks(range(len(loc)))
    ax_loc.set_yticklabels(labels)
    for i, s in enumerate(shares):
        ax_loc.text(s, i, " %.0f%%" % s, va="center", fontsize=8)
    ax_loc.set(xlabel="share of the total misfit [%]", title="where the gap lives (largest shares)")
    ax_loc.set_xlim(0, max(shares + [1.0]) * 1.15)
    ax_loc.grid(axis="x", alpha=0.3)
    if not loc:
        ax_loc.text(0.5, 0.5, "no localization entries", ha="center", transform=ax_loc.transAxes)
    # Right: RMS(measured - simulated) per phase, pressure on top and height below.
    phases = PHASES[:-1]  # landed is excluded
    x, w = np.arange(len(phases)), 0.38
    for r, (sig, sfx, scale, unit, name) in enumerate(
            [("p", "pa", 1e-3, "kPa", "pressure"), ("h", "m", 1e3, "mm", "height")]):
        ax = fig.add_subplot(gs[r, 1])
        for k, (model, color, lab) in enumerate([("nominal", "tab:red", "before: nominal model"),
                                                 ("after", "tab:blue", after_label(rep))]):
            vals = []
            for p in phases:
                res = [(d["%s_meas_%s" % (sig, sfx)] - d["%s_%s_%s" % (sig, model, sfx)])[ph == p]
                       for _, d, ph in traces]
                vals.append(rms(np.concatenate(res)) * scale)
            ax.bar(x + (k - 0.5) * w, vals, w, color=color, label=lab)
        ax.set_xticks(x)
        ax.set_xticklabels(phases)
        ax.set(ylabel="RMS residual [%s]" % unit,
               title="%s: RMS(measured − simulated) per phase, all runs" % name)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(verdict_text(rep), x=0.02, ha="left", fontsize=12)
    fig.tight_layout()
    path = os.path.join(out_dir, "residual_by_phase.png")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def plot_loops(out_dir, rep, runs):
    """hp_loops.png: height vs pressure per run, measured / nominal / after, landed excluded."""
    ncol = min(4, len(runs))
    nrow = int(np.ceil(len(runs) / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.8 * nrow + 0.6), squeeze=False)
    for i, (meta, d, ph) in enumerate(runs):
        ax = axes.flat[i]
        keep = ph != "landed"
        for model, style, color, lw, z, lab in [
                ("meas", "-", "0.1", 0.7, 3, "measured"),
                ("nominal", "--", "tab:red", 1.2, 2, "before: nominal model"),
                ("after", "-", "tab:blue", 1.8, 1, after_label(rep))]:
            ax.plot(d["p_%s_pa" % model][keep] * 1e-3, d["h_%s_m" % model][keep] * 1e3,
                    style, color=color, lw=lw, zorder=z, label=lab)
        ax.set(xlabel="pressure [kPa]", ylabel="height [mm]", title=run_title(meta))
        ax.title.set_fontsize(9)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(runs):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=8)
    fig.suptitle("height vs pressure (landed excluded) — " + verdict_text(rep), fontsize=11)
    fig.tight_layout()
    path = os.path.join(out_dir, "hp_loops.png")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def main():
    if len(sys.argv) != 2:
        fail("usage: plot_gap_report.py DIR")
    out_dir = sys.argv[1]
    if not os.path.isdir(out_dir):
        fail("report directory %s not found" % out_dir)
    rep = load_report(out_dir)
    traces = load_traces(out_dir, rep)
    runs = traces[:MAX_RUNS]  # withheld first, then by name
    written = [plot_traces(out_dir, rep, runs), plot_residuals(out_dir, rep, traces),
               plot_loops(out_dir, rep, runs)]
    written += [plot_cause(out_dir, rep, runs, c) for c in runs[0][0]["causes"]]
    print("wrote:")
    for p in written:
        print("  " + p)


if __name__ == "__main__":
    main()
