#!/usr/bin/env python3
"""Diagnoses many datasets (a fleet's nightly recordings, a folder of rig runs) across this
machine's cores and prints one summary table.

Each PATH is a dataset (a directory with run CSVs, bags or a dataset.yaml) or a folder whose
sub-directories are datasets. Every dataset is diagnosed by `gap diagnose DATASET --out
OUT/<name>` (extra options after `--` go to every diagnosis), --jobs at a time; a progress line
per finished dataset gives the time left. OUT/summary.md and OUT/summary.json hold the table:
dataset, verdict, named effects, calibrated parameters, withheld nrmse before and after, time.

Across several machines, use an existing engine on the same command per dataset (doc/gap_diagnosis.md,
"Many datasets"). Exit code 0 when every dataset was diagnosed, 1 when one failed (its error is in
the table), 2 for a bad command line.

usage: gap_batch.py PATH... --out DIR [--jobs N] [--gap PATH] [-- DIAGNOSE-OPTIONS...]
"""
import argparse
import concurrent.futures
import json
import os
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_GAP = os.path.join(HERE, "..", "build", "devel", "lib", "nursing_bed", "gap")
RUN_SUFFIXES = (".csv", ".bag")


def is_dataset(path):
    names = os.listdir(path)
    return "dataset.yaml" in names or any(n.endswith(RUN_SUFFIXES) for n in names)


def datasets_of(paths):
    """(name, path) of every dataset under the given paths, in a stable order."""
    found = []
    for path in paths:
        if not os.path.isdir(path):
            raise ValueError("%s: not a directory" % path)
        if is_dataset(path):
            found.append(path)
            continue
        subs = sorted(os.path.join(path, d) for d in os.listdir(path) if os.path.isdir(os.path.join(path, d)))
        sets = [d for d in subs if is_dataset(d)]
        if not sets:
            raise ValueError("%s: neither a dataset (run CSVs, bags, dataset.yaml) nor a folder of datasets" % path)
        found += sets
    names = [os.path.basename(os.path.normpath(p)) for p in found]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError("two datasets share the name %s: give them distinct directory names" % ", ".join(dupes))
    return list(zip(names, found))


def summarise(name, report_dir, elapsed, error):
    row = {"dataset": name, "elapsed_s": round(elapsed, 1)}
    if error is not None:
        row.update({"verdict": "error", "error": error})
        return row
    with open(os.path.join(report_dir, "report.json")) as f:
        report = json.load(f)
    verdict = report["verdict"]
    moved = [p for p in report.get("calibration", {}).get("parameters", []) if p.get("moved")]
    shrink = report.get("shrinkage", {})
    row.update({
        "verdict": verdict["status"],
        "effects": verdict.get("effects", []),
        "calibrated": {p["name"]: p["value"] for p in moved},
        "withheld_nrmse_before": shrink.get("withheld_nrmse_before"),
        "withheld_nrmse_after": shrink.get("withheld_nrmse_after"),
    })
    return row


def table(rows):
    def num(v):
        return "" if v is None else "%.4g" % v

    lines = ["| dataset | verdict | effects | calibrated | withheld nrmse before → after | time [s] |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        calibrated = ", ".join("%s=%.4g" % kv for kv in sorted(r.get("calibrated", {}).items()))
        lines.append("| %s | %s | %s | %s | %s | %.0f |" % (
            r["dataset"], r["verdict"] if r["verdict"] != "error" else "error: " + r["error"].splitlines()[-1][:80],
            ", ".join(r.get("effects", [])), calibrated,
            "%s → %s" % (num(r.get("withheld_nrmse_before")), num(r.get("withheld_nrmse_after")))
            if r["verdict"] != "error" else "", r["elapsed_s"]))
    return "\n".join(lines) + "\n"


def main():
    argv = sys.argv[1:]
    extra = []
    if "--" in argv:
        extra = argv[argv.index("--") + 1:]
        argv = argv[:argv.index("--")]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="+", metavar="PATH", help="a dataset or a folder of datasets")
    ap.add_argument("--out", required=True, help="directory for the reports and the summary (created)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="datasets diagnosed side by side (default: the number of cores)")
    ap.add_argument("--gap", default=DEFAULT_GAP, help="the gap executable")
    args = ap.parse_args(argv)
    if args.jobs < 1:
        ap.error("--jobs must be at least 1")
    if not os.path.isfile(args.gap):
        ap.error("--gap: no executable at %s (build the package first)" % args.gap)
    try:
        sets = datasets_of(args.paths)
    except (ValueError, OSError) as e:
        ap.error(str(e))
    if os.path.isdir(args.out) and os.listdir(args.out):
        ap.error("--out %s exists and is not empty" % args.out)
    os.makedirs(args.out, exist_ok=True)

    started = time.time()
    lock = threading.Lock()
    finished = [0]

    def one(item):
        name, path = item
        report_dir = os.path.join(args.out, name)
        t0 = time.time()
        run = subprocess.run([args.gap, "diagnose", path, "--out", report_dir] + extra,
                             capture_output=True, text=True)
        elapsed = time.time() - t0
        error = None if run.returncode == 0 else (run.stderr.strip() or "exit code %d" % run.returncode)
        row = summarise(name, report_dir, elapsed, error)
        with lock:
            finished[0] += 1
            spent = time.time() - started
            left = spent / finished[0] * (len(sets) - finished[0])
            print("[%d/%d] %-40s -> %-24s (%.0f s; about %.0f s left)" % (
                finished[0], len(sets), name, row["verdict"] + ("" if not row.get("effects") else
                                                               ": " + "+".join(row["effects"])), elapsed, left),
                  flush=True)
        return row

    with concurrent.futures.ThreadPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one, sets))

    summary = table(rows)
    with open(os.path.join(args.out, "summary.md"), "w") as f:
        f.write(summary)
    with open(os.path.join(args.out, "summary.json"), "w") as f:
        json.dump({"datasets": rows, "wall_s": round(time.time() - started, 1)}, f, indent=1)
    print()
    print(summary, end="")
    print("%d datasets in %.0f s; summary in %s" % (len(rows), time.time() - started,
                                                    os.path.join(args.out, "summary.md")))
    return 1 if any(r["verdict"] == "error" for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
