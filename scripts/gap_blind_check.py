#!/usr/bin/env python3
"""Blind check of the gap diagnosis (issue: sim-to-real gap; doc/gap_diagnosis.md).

For every candidate effect (several seeds, random magnitudes in the documented range), clean
data, and every effect the generator can plant that is not a candidate: `gap synth` writes a
dataset and its truth.json, `gap diagnose` diagnoses it WITHOUT the truth (truth.json is moved
out of the dataset first), and the verdict is compared with the truth. Prints the confusion
matrix and the acceptance rates:
  - single candidate effects named top-1 (verdict "explained" by exactly that effect) >= 90 %
  - clean data gives "none" in every case
  - out-of-library effects give "unexplained" (not a wrong name) in >= 70 %
  - median withheld nrmse shrink >= 70 % where the effect is named
Exit code 0 when all four hold, 1 otherwise, 2 for a bad command line.

usage: gap_blind_check.py --out DIR [--protocol small|standard] [--seeds N] [--seed-base B]
                          [--gap PATH] [--junit FILE] [--cases NAME,...]
"""
import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
import xml.sax.saxutils as su

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_GAP = os.path.join(HERE, "..", "build", "devel", "lib", "nursing_bed", "gap")

TOP1_MIN, NONE_MIN, UNEXPLAINED_MIN, SHRINK_MIN = 0.90, 1.00, 0.70, 0.70


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


def run_case(gap, out_dir, kind, effect, seed, protocol):
    """Synthesise, hide the truth, diagnose; returns the case record."""
    case = f"{effect or 'clean'}_s{seed}"
    data = os.path.join(out_dir, "data", case)
    report_dir = os.path.join(out_dir, "reports", case)
    shutil.rmtree(data, ignore_errors=True)
    shutil.rmtree(report_dir, ignore_errors=True)
    cmd = [gap, "synth", "--out", data, "--seed", str(seed), "--protocol", protocol]
    if effect:
        cmd += ["--effect", effect]
    subprocess.run(cmd, capture_output=True, text=True, check=True)
    # The diagnosis must not see the truth: move it out of the dataset.
    truth_path = os.path.join(out_dir, "truth", case + ".json")
    os.makedirs(os.path.dirname(truth_path), exist_ok=True)
    shutil.move(os.path.join(data, "truth.json"), truth_path)
    with open(truth_path) as f:
        truth = json.load(f)
    t0 = time.time()
    diag = subprocess.run([gap, "diagnose", data, "--out", report_dir, "--no-plots"], capture_output=True, text=True)
    elapsed = time.time() - t0
    if diag.returncode != 0:
        return {"case": case, "kind": kind, "truth": effect or "clean", "verdict": "error",
                "status": "error", "error": diag.stderr.strip()[-500:], "elapsed_s": elapsed}
    with open(os.path.join(report_dir, "report.json")) as f:
        report = json.load(f)
    status = report["verdict"]["status"]
    named = report["verdict"]["effects"]
    verdict = "+".join(named) if status == "explained" else status
    shrink = report["shrinkage"]
    before, after = shrink["withheld_nrmse_before"], shrink["withheld_nrmse_after"]
    top_candidate = "+".join(report["candidates"][0]["effects"]) if report["candidates"] else ""
    return {"case": case, "kind": kind, "truth": effect or "clean", "verdict": verdict, "status": status,
            "truth_params": truth["effects"][0]["params"] if truth["effects"] else {},
            "top_candidate": top_candidate, "withheld_before": before, "withheld_after": after,
            "shrink": (1.0 - after / before) if (before and after is not None and before > 0) else None,
            "elapsed_s": elapsed}


def confusion(cases, columns):
    rows = {}
    for c in cases:
        rows.setdefault(c["truth"], {}).setdefault(c["verdict"], 0)
        rows[c["truth"]][c["verdict"]] += 1
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
    ap.add_argument("--cases", help="comma-separated subset of effects (clean = no effect)")
    args = ap.parse_args()
    if args.seeds < 1:
        ap.error("--seeds must be at least 1")
    if not os.path.isfile(args.gap):
        ap.error(f"--gap: no executable at {args.gap} (build the package first)")

    candidates, others = effect_lists(args.gap)
    plan = [("candidate", e) for e in candidates] + [("clean", None)] + [("out_of_library", e) for e in others]
    if args.cases:
        wanted = set(args.cases.split(","))
        plan = [p for p in plan if (p[1] or "clean") in wanted]
    os.makedirs(args.out, exist_ok=True)
    cases = []
    started = time.time()
    total = len(plan) * args.seeds
    for kind, effect in plan:
        for k in range(args.seeds):
            seed = args.seed_base + k
            c = run_case(args.gap, args.out, kind, effect, seed, args.protocol)
            cases.append(c)
            print(f"[{len(cases)}/{total}] {c['case']:<36} -> {c['verdict']:<28} "
                  f"shrink {c.get('shrink') if c.get('shrink') is None else round(c['shrink'], 3)}  "
                  f"({c['elapsed_s']:.1f} s)", flush=True)

    single = [c for c in cases if c["kind"] == "candidate"]
    clean = [c for c in cases if c["kind"] == "clean"]
    ool = [c for c in cases if c["kind"] == "out_of_library"]
    named_right = [c for c in single if c["verdict"] == c["truth"]]
    shrinks = [c["shrink"] for c in named_right if c["shrink"] is not None]
    rates = {
        "top1": len(named_right) / len(single) if single else None,
        "clean_none": sum(c["verdict"] == "none" for c in clean) / len(clean) if clean else None,
        "out_of_library_unexplained": sum(c["verdict"] == "unexplained" for c in ool) / len(ool) if ool else None,
        "median_withheld_shrink": statistics.median(shrinks) if shrinks else None,
    }
    limits = {"top1": TOP1_MIN, "clean_none": NONE_MIN, "out_of_library_unexplained": UNEXPLAINED_MIN,
              "median_withheld_shrink": SHRINK_MIN}
    passed = {k: (v is None or v >= limits[k]) for k, v in rates.items()}
    matrix = confusion(cases, ["none", "unexplained"] + candidates)
    elapsed = time.time() - started

    def pct(v):
        return "–" if v is None else f"{100 * v:.0f} %"

    summary = [
        f"Blind check: protocol {args.protocol}, {args.seeds} seeds per effect (from {args.seed_base}), "
        f"{len(cases)} datasets, {elapsed:.0f} s.",
        "",
        matrix,
        "",
        "| criterion | result | required |", "|---|---|---|",
        f"| single effects named top-1 | {pct(rates['top1'])} ({len(named_right)}/{len(single)}) | >= 90 % |",
        f"| clean data gives none | {pct(rates['clean_none'])} | 100 % |",
        f"| out-of-library effect gives unexplained | {pct(rates['out_of_library_unexplained'])} | >= 70 % |",
        f"| median withheld nrmse shrink when named | {pct(rates['median_withheld_shrink'])} | >= 70 % |",
    ]
    text = "\n".join(summary)
    print()
    print(text)
    with open(os.path.join(args.out, "blind_check.md"), "w") as f:
        f.write(text + "\n\nCases:\n\n| case | truth params | verdict | withheld nrmse before -> after |\n|---|---|---|---|\n")
        for c in cases:
            params = ", ".join(f"{k}={v:.3g}" for k, v in c.get("truth_params", {}).items())
            wb, wa = c.get("withheld_before"), c.get("withheld_after")
            f.write(f"| {c['case']} | {params} | {c['verdict']} | "
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
