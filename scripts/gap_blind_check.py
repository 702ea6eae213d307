#!/usr/bin/env python3
"""Blind check of the gap diagnosis (doc/gap_diagnosis.md).

For every candidate effect (several seeds, random magnitudes in the documented range), clean
data, and every effect the generator can plant that is not a candidate: `gap synth` writes a
dataset and its truth.json, `gap diagnose` diagnoses it WITHOUT the truth (truth.json is moved
out of the dataset first), and the verdict is compared with the truth. Prints the confusion
matrix and the pass rates against these criteria:
  - single candidate effects named top-1 (verdict "explained" by exactly that effect) >= 90 %
  - clean data gives "none" in every case
  - out-of-library effects give "unexplained" or "discovered" (not a wrong name) in >= 70 %
  - median withheld nrmse shrink >= 80 % where effects are named
and, for the calibration (doc/gap_calibration.md), datasets whose rig differs from the
model's parameter file (`gap synth --airbag-param`, magnitudes drawn from the seed):
  - parameter mismatch alone (film stiffness +-5-20 %, gusset +-1-3 mm, dead volume x0.5-3,
    plate mass +-20 %) gives "calibrated" with exactly that parameter moved, or honestly "none"
    when the mismatch is below the line (less than 6 standard errors of the fit, or a rig the
    nominal model fits within the noise on the withheld runs, chi2/n <= 1.5) >= 90 %
  - mismatch + one effect: the effect named >= 90 %
  - pairs (leak + heat transfer, inflow bias + sensor lag, viscoelasticity + friction, leak +
    supply line): both named >= 80 %
  - valve-driven runs without a flow meter (inlet area off, a leak): leak named and the inlet
    area within 10 % >= 90 %
  - clean data: "none" and no parameter moved, every time
and for runs without a height sensor (`gap synth --no-height`, flow meter present; in the
standard matrix, or with --cases no_height):
  - clean data: "none" and no parameter moved, every time
  - a leak (1.5e-8 m^2), heat exchange (10 W/(m^2 K)) and an inflow bias each named >= 2/3
and, only with --cases distortion, every channel distortion gap synth can plant (`--distort`,
each kind on each channel, magnitudes from a fifth of the plausible bound to the bound, either
sign; log-uniform over the plausible range for lags; valve command and supply on runs driven
through the valves):
  - the right channel and kind named alone, magnitude within 25 % >= 80 % (also counted: named,
    or named by the report as what these runs cannot tell from the verdict's)
  - never a physical effect named, every time
Exit code 0 when all hold, 1 otherwise, 2 for a bad command line.

usage: gap_blind_check.py --out DIR [--protocol small|standard] [--seeds N] [--seed-base B]
                          [--extended-seeds M] [--gap PATH] [--junit FILE] [--cases NAME,...] [--jobs N] [--resume]
"""
import argparse
import concurrent.futures
import json
import math
import os
import random
import shutil
import statistics
import subprocess
import sys
import threading
import time
import xml.sax.saxutils as su
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_GAP = os.path.join(HERE, "..", "devel", "lib", "nursing_bed", "gap")

TOP1_MIN, NONE_MIN, UNEXPLAINED_MIN, SHRINK_MIN = 0.90, 1.00, 0.70, 0.80
MISMATCH_MIN, MISMATCH_EFFECT_MIN, PAIR_MIN, VALVE_MIN = 0.90, 0.90, 0.80, 0.90
NO_HEIGHT_NONE_MIN, NO_HEIGHT_NAMED_MIN = 1.00, 2.0 / 3.0
DISTORTION_NAMED_MIN, DISTORTION_NO_PHYSICAL_MIN = 0.80, 1.00
# Planted distortions: magnitudes from this share of the plausible bound up; named within this.
DISTORTION_FLOOR, DISTORTION_REL_TOL = 0.2, 0.25
# Channels that exist only on runs driven through the valves (no flow meter).
VALVE_CHANNELS = ("valve_cmd", "supply")
# A mismatch is "too small to matter" below this many standard errors of the calibration's fit.
SMALL_MISMATCH_SE = 6.0
# ... or when the unmoved (nominal) model fits the withheld runs within the noise: chi2 per
# sample in noise-floor units at most this (the diagnosis's own "within the noise").
NOISE_CHI2 = 1.5
NOMINAL = {"film_stiffness_scale": 1.0, "gusset_height_m": 0.079, "dead_volume_m3": 5.0e-6,
           "plate_mass_kg": 0.06118297278, "inlet_area_m2": 1.5e-5}
PAIRS = [("leak", "heat_transfer"), ("inflow_bias", "pressure_sensor_lag"),
         ("membrane_viscoelasticity", "plate_friction"), ("leak", "supply_line")]
# Mid-range magnitudes of the pairs' effects (parameters not given are drawn from the seed).
PAIR_PARAMS = {"leak": "leak:leak_area_m2=1.5e-8", "heat_transfer": "heat_transfer:heat_transfer_coefficient_w_m2_k=8"}
# Runs without a height sensor: clean, and these effects (the inflow bias drawn from the seed).
NO_HEIGHT_CASES = [("clean", []), ("leak", ["leak:leak_area_m2=1.5e-8"]),
                   ("heat_transfer", ["heat_transfer:heat_transfer_coefficient_w_m2_k=10"]),
                   ("inflow_bias", ["inflow_bias"])]


def draw_mismatch(param, rng):
    """A parameter mismatch within the blind check's ranges, sign and size from `rng`."""
    sign = rng.choice([-1.0, 1.0])
    if param == "film_stiffness_scale":
        return 1.0 + sign * rng.uniform(0.05, 0.20)
    if param == "gusset_height_m":
        return NOMINAL[param] + sign * rng.uniform(0.001, 0.003)
    if param == "dead_volume_m3":
        return NOMINAL[param] * rng.choice([rng.uniform(0.5, 0.8), rng.uniform(1.5, 3.0)])
    if param == "plate_mass_kg":
        return NOMINAL[param] * (1.0 + sign * rng.uniform(0.10, 0.20))
    return NOMINAL[param] * rng.uniform(0.8, 1.25)


def calibration_plan(candidates, seeds, seed_base):
    """The calibration cases: (kind, name, effects, airbag params, synth flags, seed)."""
    plan = []
    for k in range(seeds):
        seed = seed_base + k
        rng = random.Random(seed * 7919)
        for param in ["film_stiffness_scale", "gusset_height_m", "dead_volume_m3", "plate_mass_kg"]:
            plan.append(("mismatch", param, [], {param: draw_mismatch(param, rng)}, [], seed))
        for param in ["film_stiffness_scale", "gusset_height_m"]:
            effect = candidates[rng.randrange(len(candidates))]
            plan.append(("mismatch_effect", f"{param}+{effect}", [effect], {param: draw_mismatch(param, rng)}, [],
                         seed))
        for a, b in PAIRS:
            plan.append(("pair", f"{a}+{b}", [PAIR_PARAMS.get(a, a), PAIR_PARAMS.get(b, b)], {}, [], seed))
        plan.append(("valve", "leak_no_meter", ["leak"], {"inlet_area_m2": draw_mismatch("inlet_area_m2", rng)},
                     ["--no-flow-meter"], seed))
    return plan


def no_height_plan(seeds, seed_base):
    """The cases without a height sensor: (kind, name, effects, airbag params, synth flags, seed)."""
    return [("no_height", name, effects, {}, ["--no-height"], seed_base + k)
            for name, effects in NO_HEIGHT_CASES for k in range(seeds)]


def distortion_kinds(gap):
    """(channel, kind, lo, hi, log) of every distortion `gap synth --distort` plants, from its --help."""
    out = subprocess.run([gap, "synth", "--help"], capture_output=True, text=True, check=True).stdout
    listing = out.split("distortions (--distort", 1)[1].split("effects and their parameters:", 1)[0]
    kinds = []
    for line in listing.splitlines():
        line = line.strip()
        if "=VALUE" not in line or "plausible" not in line:
            continue
        channel, kind = line.split("=VALUE", 1)[0].split(":")
        lo, hi = line.split("plausible", 1)[1].split(",", 1)[0].replace("(log)", "").split("..")
        kinds.append((channel, kind, float(lo), float(hi), "(log)" in line.split("admissible")[0]))
    return kinds


def draw_distortion(lo, hi, log, rng):
    """A planted magnitude: log-uniform over [lo, hi] for a lag, else from DISTORTION_FLOOR of the
    bound to the bound (log-uniform), either sign."""
    if log:
        return math.exp(rng.uniform(math.log(lo), math.log(hi)))
    bound = max(abs(lo), abs(hi))
    return rng.choice([-1.0, 1.0]) * bound * math.exp(rng.uniform(math.log(DISTORTION_FLOOR), 0.0))


def distortion_plan(gap, seeds, seed_base):
    """Each channel distortion on its runs: (kind, name, effects, airbag params, synth flags, seed)."""
    plan = []
    for channel, kind, lo, hi, log in distortion_kinds(gap):
        for k in range(seeds):
            seed = seed_base + k
            rng = random.Random(seed * 7919 + zlib.crc32(f"{channel}:{kind}".encode()))
            value = draw_distortion(lo, hi, log, rng)
            flags = ["--distort", f"{channel}:{kind}={value:.6g}"]
            if channel in VALVE_CHANNELS:
                flags.append("--no-flow-meter")
            plan.append(("distortion", f"{channel}_{kind}", [], {}, flags, seed))
    return plan


def effect_lists(gap):
    """Candidate and non-candidate effect names, from `gap synth --help`."""
    out = subprocess.run([gap, "synth", "--help"], capture_output=True, text=True, check=True).stdout
    candidates, others = [], []
    listing = out.split("effects and their parameters:", 1)[1]
    for line in listing.splitlines():
        line = line.strip()
        if not line or ":" not in line:
            continue
        name = line.split(":", 1)[0].strip()
        if "(not a candidate)" in name:
            others.append(name.replace("(not a candidate)", "").strip())
        else:
            candidates.append(name)
    return candidates, others


def case_name(case_spec):
    kind, name, _, _, _, seed = case_spec
    return f"{kind}_{name}_s{seed}" if kind not in ("candidate", "clean", "out_of_library") else f"{name}_s{seed}"


def case_paths(out_dir, case):
    """Dataset, report directory and (hidden) truth file of one case."""
    return (os.path.join(out_dir, "data", case), os.path.join(out_dir, "reports", case),
            os.path.join(out_dir, "truth", case + ".json"))


def synthesise(gap, out_dir, case_spec, protocol):
    """Write the case's dataset, then move its truth out of it: the diagnosis must not see it."""
    _, _, effects, airbag, flags, seed = case_spec
    data, report_dir, truth_path = case_paths(out_dir, case_name(case_spec))
    shutil.rmtree(data, ignore_errors=True)
    shutil.rmtree(report_dir, ignore_errors=True)
    cmd = [gap, "synth", "--out", data, "--seed", str(seed), "--protocol", protocol] + flags
    for e in effects:
        cmd += ["--effect", e]
    for k, v in airbag.items():
        cmd += ["--airbag-param", f"{k}={v!r}"]
    subprocess.run(cmd, capture_output=True, text=True, check=True)
    os.makedirs(os.path.dirname(truth_path), exist_ok=True)
    shutil.move(os.path.join(data, "truth.json"), truth_path)


def diagnose(gap, out_dir, case_spec):
    """Run `gap diagnose` blind; its wall time is kept beside the report (for --resume)."""
    data, report_dir, _ = case_paths(out_dir, case_name(case_spec))
    t0 = time.time()
    diag = subprocess.run([gap, "diagnose", data, "--out", report_dir, "--no-plots"], capture_output=True, text=True)
    elapsed = time.time() - t0
    if diag.returncode == 0:
        with open(os.path.join(report_dir, "elapsed_s"), "w") as f:
            f.write(f"{elapsed:.1f}\n")
    return diag, elapsed


def read_record(out_dir, case_spec, diag_error=None, elapsed=None):
    """The case record: its truth, and the verdict read from the report."""
    kind, name, _, airbag, _, _ = case_spec
    case = case_name(case_spec)
    _, report_dir, truth_path = case_paths(out_dir, case)
    with open(truth_path) as f:
        truth = json.load(f)
    planted = truth["effects"] + truth.get("distortions", [])
    record = {"case": case, "kind": kind, "truth": name, "truth_effects": sorted(e["name"] for e in planted),
              "airbag": airbag,
              "truth_params": {k: v for e in planted for k, v in e["params"].items()}}
    if elapsed is None and os.path.isfile(os.path.join(report_dir, "elapsed_s")):
        with open(os.path.join(report_dir, "elapsed_s")) as f:
            elapsed = float(f.read())
    record["elapsed_s"] = elapsed
    if diag_error is not None:
        record.update({"verdict": "error", "status": "error", "error": diag_error[-500:], "moved": {}})
        return record
    with open(os.path.join(report_dir, "report.json")) as f:
        report = json.load(f)
    status = report["verdict"]["status"]
    named = report["verdict"]["effects"]
    params = report.get("calibration", {}).get("parameters", [])
    moved = {p["name"]: p["value"] for p in params if p["moved"]}
    verdict = "+".join(named) if status == "explained" else status
    if status == "calibrated":
        verdict = "calibrated(" + ",".join(sorted(moved)) + ")"
    shrink = report["shrinkage"]
    before, after = shrink["withheld_nrmse_before"], shrink["withheld_nrmse_after"]
    record.update({"verdict": verdict, "status": status, "named": sorted(named), "moved": moved,
                   "named_params": report["verdict"].get("params", {}),
                   # explanations the report says these runs cannot tell from the verdict's
                   "undecided": [(c["explanations"][1], c.get("rival_params", {}))
                                 for c in report.get("identifiability", [])],
                   "std_errors": {p["name"]: p["std_error"] for p in params},
                   # the calibrated model on the withheld runs (the nominal one when nothing moved)
                   "withheld_chi2_calibrated": report.get("calibration", {}).get("withheld_chi2_per_sample"),
                   "top_candidate": "+".join(report["candidates"][0]["effects"]) if report["candidates"] else "",
                   "withheld_before": before, "withheld_after": after,
                   "shrink": (1.0 - after / before) if (before and after is not None and before > 0) else None})
    return record


def run_case(gap, out_dir, case_spec, protocol, resume=False):
    """Synthesise, hide the truth, diagnose; returns the case record. With `resume`, a case whose
    report and truth are already there is read back instead of run again."""
    _, report_dir, truth_path = case_paths(out_dir, case_name(case_spec))
    if resume and os.path.isfile(os.path.join(report_dir, "report.json")) and os.path.isfile(truth_path):
        return read_record(out_dir, case_spec)
    synthesise(gap, out_dir, case_spec, protocol)
    diag, elapsed = diagnose(gap, out_dir, case_spec)
    return read_record(out_dir, case_spec, diag.stderr.strip() if diag.returncode != 0 else None, elapsed)


def mismatch_right(c):
    """Calibrated with exactly the mismatched parameter; or none where it is below the line."""
    (param, value), = c["airbag"].items()
    if c["status"] == "calibrated":
        return set(c["moved"]) == {param}
    if c["status"] != "none" or c["moved"]:
        return False
    # Below the line: the fit cannot resolve the move (under SMALL_MISMATCH_SE standard errors),
    # or the rig with the mismatch is one the nominal model already fits within the noise on the
    # withheld runs (NOISE_CHI2 per sample): the data cannot see it.
    se = c.get("std_errors", {}).get(param)
    chi2 = c.get("withheld_chi2_calibrated")  # nothing moved here: the nominal model's
    unseen = chi2 is not None and chi2 <= NOISE_CHI2
    c["below_line"] = se is None or abs(value - NOMINAL[param]) < SMALL_MISMATCH_SE * se or unseen
    return c["below_line"]


def distortion_right(c):
    """The planted distortion named alone, its planted parameter within DISTORTION_REL_TOL. Also
    marks c["undecided_right"]: named, or the one the report says these runs cannot tell from the
    verdict's, within the tolerance."""
    # The planted parameter: the one away from 0 (inflow_bias has two, one planted).
    param, value = next((k, v) for k, v in c["truth_params"].items() if v != 0.0)

    def within(params):
        named = params.get(param)
        return None if named is None else abs(named / value - 1.0)

    right = c["status"] == "explained" and c["named"] == c["truth_effects"]
    c["magnitude_error"] = within(c["named_params"]) if right else None
    right = right and c["magnitude_error"] is not None and c["magnitude_error"] <= DISTORTION_REL_TOL
    rivals = [within(p) for name, p in c.get("undecided", []) if name.split("+") == c["truth_effects"]]
    c["undecided_right"] = right or (c["status"] == "explained" and
                                     any(e is not None and e <= DISTORTION_REL_TOL for e in rivals))
    return right


def case_right(c):
    """Whether the verdict is right for its kind."""
    kind = c["kind"]
    if kind == "distortion":
        return distortion_right(c)
    if kind == "candidate":
        return c["verdict"] == c["truth"]
    if kind == "clean":
        return c["verdict"] == "none" and not c["moved"]
    if kind == "out_of_library":
        # A drifting pressure zero is a member of the channel distortions (pressure: drift).
        if c["truth"] == "pressure_offset_drift" and c["named"] == ["pressure_drift"]:
            return True
        # Outside both lists the honest verdicts are "unexplained" and a correction the discovery
        # proved on the withheld runs ("discovered"); never a named effect.
        return c["status"] in ("unexplained", "discovered")
    if kind == "mismatch":
        return mismatch_right(c)
    if kind in ("mismatch_effect", "pair"):
        return c["status"] == "explained" and c["named"] == c["truth_effects"]
    if kind == "valve":
        truth_area = c["airbag"]["inlet_area_m2"]
        area = c["moved"].get("inlet_area_m2", NOMINAL["inlet_area_m2"])
        c["inlet_area_error"] = abs(area / truth_area - 1.0)
        return c["status"] == "explained" and c["named"] == ["leak"] and c["inlet_area_error"] <= 0.10
    if kind == "no_height":
        if c["truth"] == "clean":
            return c["verdict"] == "none" and not c["moved"]
        return c["status"] == "explained" and c["named"] == c["truth_effects"]
    return False


def seconds(value):
    return "? s" if value is None else f"{value:.1f} s"


def confusion(cases, columns):
    rows = {}
    for c in cases:
        truth = c["truth"] + (" (no height)" if c["kind"] == "no_height" else "")
        rows.setdefault(truth, {}).setdefault(c["verdict"], 0)
        rows[truth][c["verdict"]] += 1
    extra = sorted({v for r in rows.values() for v in r} - set(columns))
    cols = columns + extra
    lines = ["| truth \\ verdict | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for truth in rows:
        lines.append(f"| {truth} | " + " | ".join(str(rows[truth].get(c, "")) for c in cols) + " |")
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="working directory (datasets, reports, results)")
    ap.add_argument("--protocol", default="small", choices=["small", "standard"])
    ap.add_argument("--seeds", type=int, default=3, help="seeds per effect (default 3)")
    ap.add_argument("--seed-base", type=int, default=100, help="first seed (default 100)")
    ap.add_argument("--gap", default=DEFAULT_GAP, help="the gap executable")
    ap.add_argument("--junit", help="also write a JUnit XML result file here")
    ap.add_argument("--cases", help="comma-separated subset of cases: effect names, clean, mismatch, mismatch_effect, "
                                    "pair, valve, no_height (runs without a height sensor; in the standard "
                                    "matrix by default, in the small one only when named here), distortion "
                                    "(every plantable channel distortion; only when named here)")
    ap.add_argument("--extended-seeds", type=int, default=1,
                    help="seeds of each calibration case (mismatch, mismatch + effect, pairs, valve-driven; default 1)")
    ap.add_argument("--jobs", type=int, default=1,
                    help="cases diagnosed side by side (default 1; each diagnosis also uses its own threads)")
    ap.add_argument("--resume", action="store_true",
                    help="read back cases whose report is already in --out instead of running them again "
                         "(a long matrix run in parts)")
    args = ap.parse_args()
    if args.jobs < 1:
        ap.error("--jobs must be at least 1")
    if args.seeds < 1:
        ap.error("--seeds must be at least 1")
    if not os.path.isfile(args.gap):
        ap.error(f"--gap: no executable at {args.gap} (build the package first)")

    candidates, others = effect_lists(args.gap)
    plan = []
    for kind, effect in [("candidate", e) for e in candidates] + [("clean", None)] + \
            [("out_of_library", e) for e in others]:
        for k in range(args.seeds):
            plan.append((kind, effect or "clean", [effect] if effect else [], {}, [], args.seed_base + k))
    plan += calibration_plan(candidates, args.extended_seeds, args.seed_base)
    wanted = set(args.cases.split(",")) if args.cases else set()
    if args.protocol == "standard" or "no_height" in wanted:
        plan += no_height_plan(args.seeds, args.seed_base)
    if "distortion" in wanted:
        plan += distortion_plan(args.gap, args.seeds, args.seed_base)
    if args.cases:
        # no_height selects those cases alone; a name selects it among the height-sensor cases
        plan = [p for p in plan if p[0] in wanted or (p[1] in wanted and p[0] != "no_height")]
    os.makedirs(args.out, exist_ok=True)
    started = time.time()
    finished = [0]
    print_lock = threading.Lock()

    def one(spec):
        c = run_case(args.gap, args.out, spec, args.protocol, args.resume)
        c["right"] = case_right(c)
        with print_lock:
            finished[0] += 1
            print(f"[{finished[0]}/{len(plan)}] {c['case']:<48} -> {c['verdict']:<36} {'ok ' if c['right'] else 'BAD'} "
                  f"shrink {c.get('shrink') if c.get('shrink') is None else round(c['shrink'], 3)}  "
                  f"({seconds(c['elapsed_s'])})", flush=True)
        return c

    # Cases are independent (own dataset and report directories): --jobs of them side by side,
    # the slow kinds (joint refits of two effects) first so the jobs end together.
    slow_first = sorted(range(len(plan)), key=lambda i: plan[i][0] not in ("pair", "mismatch_effect"))
    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        done = dict(zip(slow_first, pool.map(one, [plan[i] for i in slow_first])))
    cases = [done[i] for i in range(len(plan))]

    def rate(kind):
        of_kind = [c for c in cases if c["kind"] == kind]
        return (sum(c["right"] for c in of_kind) / len(of_kind) if of_kind else None), of_kind

    named = [c for c in cases if c["right"] and c["kind"] in ("candidate", "mismatch_effect", "pair", "valve")
             or (c["right"] and c["kind"] == "no_height" and c["truth"] != "clean")]
    shrinks = [c["shrink"] for c in named if c["shrink"] is not None]
    rates, counts = {}, {}
    for key, kind in [("top1", "candidate"), ("clean_none", "clean"), ("out_of_library_unexplained", "out_of_library"),
                      ("mismatch_calibrated", "mismatch"), ("mismatch_effect_named", "mismatch_effect"),
                      ("pairs_named", "pair"), ("valve_driven_leak_and_inlet", "valve")]:
        rates[key], of_kind = rate(kind)
        counts[key] = f"{sum(c['right'] for c in of_kind)}/{len(of_kind)}"
    no_height = [c for c in cases if c["kind"] == "no_height"]
    for key, group in [("no_height_clean_none", [c for c in no_height if c["truth"] == "clean"])] + \
            [(f"no_height_{name}_named", [c for c in no_height if c["truth"] == name])
             for name, _ in NO_HEIGHT_CASES if name != "clean"]:
        rates[key] = sum(c["right"] for c in group) / len(group) if group else None
        counts[key] = f"{sum(c['right'] for c in group)}/{len(group)}"
    distorted = [c for c in cases if c["kind"] == "distortion"]
    if distorted:
        # A physical effect: a candidate that is not a channel's member (the sensor lag, the inflow bias).
        physical = set(candidates) - {"pressure_sensor_lag", "inflow_bias"}
        clear = [c for c in distorted if not set(c.get("named", [])) & physical]
        rates["distortion_named"] = sum(c["right"] for c in distorted) / len(distorted)
        counts["distortion_named"] = f"{sum(c['right'] for c in distorted)}/{len(distorted)}"
        undecided = sum(c.get("undecided_right", False) for c in distorted)
        rates["distortion_named_or_undecided"] = undecided / len(distorted)
        counts["distortion_named_or_undecided"] = f"{undecided}/{len(distorted)}"
        rates["distortion_no_physical"] = len(clear) / len(distorted)
        counts["distortion_no_physical"] = f"{len(clear)}/{len(distorted)}"
    rates["median_withheld_shrink"] = statistics.median(shrinks) if shrinks else None
    counts["median_withheld_shrink"] = f"{len(shrinks)} named"
    limits = {"top1": TOP1_MIN, "clean_none": NONE_MIN, "out_of_library_unexplained": UNEXPLAINED_MIN,
              "mismatch_calibrated": MISMATCH_MIN, "mismatch_effect_named": MISMATCH_EFFECT_MIN,
              "pairs_named": PAIR_MIN, "valve_driven_leak_and_inlet": VALVE_MIN, "median_withheld_shrink": SHRINK_MIN,
              "no_height_clean_none": NO_HEIGHT_NONE_MIN}
    limits.update({f"no_height_{name}_named": NO_HEIGHT_NAMED_MIN for name, _ in NO_HEIGHT_CASES if name != "clean"})
    limits.update({"distortion_named": DISTORTION_NAMED_MIN, "distortion_named_or_undecided": DISTORTION_NAMED_MIN,
                   "distortion_no_physical": DISTORTION_NO_PHYSICAL_MIN})
    passed = {k: (v is None or v >= limits[k]) for k, v in rates.items()}
    matrix = confusion(cases, ["none", "unexplained"] + candidates)
    elapsed = time.time() - started

    def pct(v):
        return "–" if v is None else f"{100 * v:.0f} %"

    summary = [
        f"Blind check: protocol {args.protocol}, {args.seeds} seeds per effect and {args.extended_seeds} per "
        f"calibration case (from {args.seed_base}), "
        f"{len(cases)} datasets, {elapsed:.0f} s.",
        "",
        matrix,
        "",
        "| criterion | result | required |", "|---|---|---|",
    ] + [f"| {k} | {pct(v)} ({counts[k]}) | >= {pct(limits[k])} |" for k, v in rates.items()] + [
        "",
        "Mismatches below the line (honest none: less than "
        f"{SMALL_MISMATCH_SE:g} standard errors, or the nominal model within the noise on the withheld runs, "
        f"chi2/n <= {NOISE_CHI2:g}): " +
        (", ".join(c["case"] for c in cases if c.get("below_line")) or "none"),
    ]
    text = "\n".join(summary)
    print()
    print(text)
    with open(os.path.join(args.out, "blind_check.md"), "w") as f:
        f.write(text + "\n\nCases:\n\n| case | truth params | verdict | withheld nrmse before -> after |\n|---|---|---|---|\n")
        for c in cases:
            truth = dict(c.get("truth_params", {}), **c.get("airbag", {}))
            params = ", ".join(f"{k}={v:.4g}" for k, v in truth.items())
            wb, wa = c.get("withheld_before"), c.get("withheld_after")
            verdict = c["verdict"]
            if c.get("magnitude_error") is not None:
                verdict += f" (magnitude off {100 * c['magnitude_error']:.1f} %)"
            f.write(f"| {c['case']} | {params} | {verdict} | "
                    f"{'' if wb is None else f'{wb:.4f}'} -> {'' if wa is None else f'{wa:.4f}'} |\n")
    with open(os.path.join(args.out, "blind_check.json"), "w") as f:
        json.dump({"protocol": args.protocol, "seeds": args.seeds, "seed_base": args.seed_base, "rates": rates,
                   "passed": passed, "cases": cases}, f, indent=1)
    if args.junit:
        os.makedirs(os.path.dirname(os.path.abspath(args.junit)), exist_ok=True)
        items = []
        for k, ok in passed.items():
            body = "" if ok else f'<failure message="{k} = {pct(rates[k])}, required {pct(limits[k])}"/>'
            items.append(f'  <testcase classname="gap_blind_check" name="{k}" time="0">{body}</testcase>')
        failures = sum(not ok for ok in passed.values())
        with open(args.junit, "w") as f:
            f.write(f'<?xml version="1.0" encoding="UTF-8"?>\n<testsuite name="gap_blind_check" tests="{len(passed)}" '
                    f'failures="{failures}" errors="0">\n' + "\n".join(items) +
                    f"\n  <system-out>{su.escape(text)}</system-out>\n</testsuite>\n")
    return 0 if all(passed.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
