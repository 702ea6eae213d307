#!/usr/bin/env python3
"""The gap diagnosis on the ventilator / test-lung recordings (doc/gap_real_recordings.md).

Usage: gap_real_recordings.py GAP_BINARY OUT_DIR [--only NAME...] [--command calibrate|diagnose]

Imports each recording of test/data/respiraworks on its own (2020-06-21 with the corrected
net flow, 2020-07-01 with the venturis' uncorrected flow), runs `gap calibrate` on the corrected
ones and `gap diagnose` on the uncorrected ones, and prints one table row per recording: the
lung's set compliance and resistor, the calibrated compliance and airway resistance, the
verdict, the inflow bias fitted and named, and the model-free checks (a linear least-squares fit of
p = p0 + V/C + R1 q + R2 q|q| on the same runs, and the uncorrected volume's drift over whole
breaths less C times the change of end-expiratory pressure). Writes OUT_DIR/summary.json.
With --plots, draws data vs model vs model + named cause for the first run of two recordings.
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys

import numpy as np
import yaml

NAN = float("nan")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "test", "data", "respiraworks")
SETS = [  # (folder, mapping, command)
    ("2020-06-21-RunForRecord2-AIR", "respiraworks_net_flow.yaml", "calibrate"),
    ("2020-07-01-Control-Tests-AIR", "respiraworks_venturi.yaml", "diagnose"),
]
CMH2O_PA = 98.0665
ML_CMH2O = 1e-6 / CMH2O_PA  # m^3/Pa of 1 mL/cmH2O
R_UNIT = CMH2O_PA / 1e-3  # Pa s/m^3 of 1 cmH2O/(L/s)
RHO = 1.204  # the mappings' gas density [kg/m^3]
Q_EFF = 0.5e-3  # flow at which the effective resistance R1 + R2 q is quoted [m^3/s]
EEP_WINDOW_S = 0.3
GAMMA = 1.4
P_AMBIENT = 101325.0


def read_run(path):
    meta, rows, names = {}, [], None
    with open(path) as f:
        for line in f:
            if line.startswith("#"):
                m = re.match(r"# (\w+): (.*)", line)
                if m:
                    meta[m.group(1)] = m.group(2).strip()
            elif names is None:
                names = line.strip().split(",")
            else:
                rows.append([float(x) if x else np.nan for x in line.strip().split(",")])
    a = np.array(rows)
    return {n: a[:, i] for i, n in enumerate(names)}, meta


def least_squares(runs):
    """C, R1, R2 of p = p0 + V/C + R1 q + R2 q|q| + s t on the runs (one p0 and s per run)."""
    blocks, ys = [], []
    for k, (d, _) in enumerate(runs):
        t, q, p = d["t_s"], d["mdot_in_kg_s"] / RHO, d["p_gauge_pa"]
        v = np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * np.diff(t))])
        cols = [v, q, q * np.abs(q)]
        for j in range(len(runs)):
            cols += [np.ones_like(t) * (j == k), (t - t[0]) * (j == k)]
        blocks.append(np.column_stack(cols))
        ys.append(p)
    x, *_ = np.linalg.lstsq(np.vstack(blocks), np.concatenate(ys), rcond=None)
    return 1.0 / x[0], x[1], x[2]


def model_free_bias(runs, compliance):
    """Inflow bias [m^3/s] of a log, model-free, over its whole breaths after the first: from the
    end of the first expiration (the last sample at PEEP before the setpoint's second rise) to the
    end of the last (the last run ends where the next breath starts), the metered volume less C
    times the change of the end-expiratory pressure (means over 0.3 s), over the time."""
    cols = {k: [] for k in ("t_s", "mdot_in_kg_s", "p_gauge_pa", "p_setpoint_gauge_pa")}
    for d, _ in runs:
        keep = d["t_s"] > (cols["t_s"][-1][-1] if cols["t_s"] else -np.inf)
        for k in cols:
            cols[k].append(d[k][keep])
    t, q, p, sp = (np.concatenate(cols[k]) for k in cols)
    q = q / RHO
    rises = np.where((sp[1:] > sp[:-1]) & (sp[:-1] <= np.min(sp) + 1.0) & (t[1:] > t[0] + 0.5))[0]
    k = rises[0]
    eep0 = np.mean(p[(t > t[k] - EEP_WINDOW_S) & (t <= t[k])])
    eep1 = np.mean(p[t > t[-1] - EEP_WINDOW_S])
    return (np.trapz(q[k:], t[k:]) - compliance * (eep1 - eep0)) / (t[-1] - t[k])


def run(cmd):
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def calibrated(report, name):
    for p in report.get("calibration", {}).get("parameters", []):
        if p["name"] == name:
            return p["value"] if p.get("moved") else p["fitted"], p.get("moved", False)
    return float("nan"), False


def one_recording(gap, folder, mapping, command, log, out):
    name = folder[:10] + "_" + os.path.basename(log).replace(".dat", "")
    ds, res = os.path.join(out, name, "data"), os.path.join(out, name, "gap")
    for d in (ds, res):
        subprocess.run(["rm", "-rf", d], check=True)
    run([gap, "import", os.path.join(ROOT, "config", "import", mapping), log, "--out", ds])
    run([gap, command, ds, "--out", res, "--no-plots"])
    report = json.load(open(os.path.join(res, "report.json")))
    runs = [read_run(f) for f in sorted(glob.glob(os.path.join(ds, "*.csv")))]
    fit_runs = [r for r in runs if r[0] is not None]
    meta = runs[0][1]
    c_set = float(meta["lung_compliance_m3_pa"])
    lung = yaml.safe_load(open(os.path.join(ROOT, "config", meta["airbag"])))
    bellows = lung["bellows"]
    # At the port: the spring's compliance plus the bellows gas' (adiabatic) compressibility.
    c_gas = bellows["dead_volume_m3"] / (GAMMA * P_AMBIENT)
    r_plate = lung["plate"]["damping_n_s_m"] / bellows["area_m2"] ** 2
    c_cal, c_moved = calibrated(report, "compliance_m3_pa")
    c_cal += c_gas
    r1, _ = calibrated(report, "airway_resistance_pa_s_m3")
    r2, _ = calibrated(report, "airway_quadratic_resistance_pa_s2_m6")
    c_ls, r1_ls, r2_ls = least_squares(fit_runs)
    verdict = report["verdict"]
    bias = NAN
    for c in report.get("candidates", []):
        if c["effects"] == ["inflow_bias"]:
            bias = c["params"]["offset_kg_s"] / RHO
    named = verdict.get("params", {}).get("offset_kg_s", NAN) / RHO if "inflow_bias" in verdict.get("effects", []) \
        else NAN
    row = {
        "recording": name, "resistor": meta["lung_resistor"], "command": command,
        "c_set_ml_cmh2o": c_set / ML_CMH2O, "c_cal_ml_cmh2o": c_cal / ML_CMH2O, "c_moved": c_moved,
        "c_error": c_cal / c_set - 1.0, "c_ls_ml_cmh2o": c_ls / ML_CMH2O,
        "r1_cal": r1 / R_UNIT, "r2_cal": r2 / R_UNIT * 1e-3, "r_eff_cal": (r1 + r2 * Q_EFF + r_plate) / R_UNIT,
        "r_eff_ls": (r1_ls + r2_ls * Q_EFF) / R_UNIT,
        "status": verdict.get("status"), "effects": verdict.get("effects", []),
        "inflow_bias_fit_ml_s": bias * 1e6, "inflow_bias_named_ml_s": named * 1e6,
        "model_free_bias_ml_s": model_free_bias(runs, c_set) * 1e6,
        "nominal_chi2_per_sample": report.get("noise", {}).get("nominal_chi2_per_sample"),
        "calibrated_chi2": report.get("calibration", {}).get("chi2"),
        "report": res,
    }
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("gap")
    ap.add_argument("out")
    ap.add_argument("--only", nargs="*", default=[])
    ap.add_argument("--command", choices=["calibrate", "diagnose"],
                    help="the same command on every recording (default: calibrate the corrected, "
                         "diagnose the uncorrected ones)")
    args = ap.parse_args()
    rows = []
    for folder, mapping, command in SETS:
        for log in sorted(glob.glob(os.path.join(DATA, folder, "covent_pc_*.dat"))):
            if args.only and not any(o in folder + "/" + os.path.basename(log) for o in args.only):
                continue
            row = one_recording(args.gap, folder, mapping, args.command or command, log, args.out)
            rows.append(row)
            print("{recording:24s} {resistor:5s} C set {c_set_ml_cmh2o:5.1f} cal {c_cal_ml_cmh2o:6.2f} "
                  "({c_error:+6.1%}) LS {c_ls_ml_cmh2o:6.2f}  R_eff cal {r_eff_cal:5.1f} LS {r_eff_ls:5.1f}  "
                  "{status} {effects} bias fit {inflow_bias_fit_ml_s:+6.2f} named {inflow_bias_named_ml_s:+6.2f} (model-free {model_free_bias_ml_s:+6.2f}) mL/s"
                  .format(**row), flush=True)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump(rows, f, indent=1)
    within = sum(abs(r["c_error"]) <= 0.10 for r in rows)
    print(f"compliance within 10 %: {within} of {len(rows)}")


if __name__ == "__main__":
    sys.exit(main())
