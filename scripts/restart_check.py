#!/usr/bin/python3
"""Terminals restarted with every cell emptied, --repeat times, scored against the rig emulator's
truth (doc/real_bed.md, "Restarts").

Starts `roslaunch nursing_bed real_bed.launch emulator:=true` (rows x cols, as soak.py; the
patient simulator with it unless simulator:=false), waits for the bed to settle flat, then every
--every-s restarts the terminals through /rig_emulator/inject_fault: silent for --silence-s, every
cell back flat and empty. For each restart and cell it measures, from the reconnection (the end
of the silence):
  - whether the cell is flagged (faulty or unverified in /bed_manager/state) within --flag-s;
  - how long until it is unflagged with the truth within 2 mm of its target (--back-s at most);
and over the whole run, as soak.py scores it, every reported height against the truth: the
cell-seconds with an unflagged error over 6 mm and the worst unflagged error. Prints a line per
restart and the totals; --json keeps them. Exit code 0 when measured, 1 when the bed never came
up or the emulator refused the restart, 2 for a bad command line.

usage: restart_check.py [--repeat N] [--rows R] [--cols C] [--json FILE] [launch args...]
e.g.   restart_check.py --repeat 10
"""
import argparse
import json
import math
import statistics
import sys
import time

import rospy

from soak import add_bed_arguments, emulated_bed, inject

BACK_M = 0.002  # a cell is back when the truth is this close to its target, unflagged


def one_restart(args, score, n_cells):
    """Restarts the terminals once; returns (flagged within --flag-s of the reconnection, seconds
    from it until back on the target the bed manager gives it then, or None) per cell."""
    at = rospy.get_time()
    if not inject("restart", [], value=args.silence_s):
        raise RuntimeError("the emulator refused the restart")
    reconnected = at + args.silence_s
    flagged, back = [False] * n_cells, [None] * n_cells
    while rospy.get_time() < reconnected + args.back_s and not rospy.is_shutdown():
        now = rospy.get_time()
        with score.lock:
            truth = score.truth[-1][1] if score.truth else None
            now_flagged = set(score.flagged_now)
            targets = {c: moves[-1][1] for c, moves in score.target_moves.items()}
        for c in range(n_cells):
            if c in now_flagged and reconnected <= now <= reconnected + args.flag_s:
                flagged[c] = True
            if (back[c] is None and now > reconnected and c not in now_flagged and truth is not None
                    and c < len(truth) and abs(truth[c] - targets.get(c, math.nan)) <= BACK_M):
                back[c] = now - reconnected
        if all(b is not None for b in back) and now > reconnected + args.flag_s:
            break
        time.sleep(0.1)
    return flagged, back


def run(args, score, n_cells):
    score.recording = True
    score.t0 = rospy.get_time()
    reps = []
    for i in range(args.repeat):
        next_at = rospy.get_time() + args.every_s
        flagged, back = one_restart(args, score, n_cells)
        times = [b for b in back if b is not None]
        rep = {"flagged": sum(flagged), "back": len(times), "back_median_s": statistics.median(times) if times else None,
               "back_max_s": max(times) if times else None, "not_back": [c for c, b in enumerate(back) if b is None],
               "not_flagged": [c for c, f in enumerate(flagged) if not f]}
        reps.append(rep)
        print("restart %d: flagged within %.1f s %d of %d; back within 2 mm %d (median %s s, max %s s)" % (
            i + 1, args.flag_s, rep["flagged"], n_cells, rep["back"],
            "%.1f" % rep["back_median_s"] if times else "-", "%.1f" % rep["back_max_s"] if times else "-"))
        sys.stdout.flush()
        while rospy.get_time() < next_at:
            time.sleep(0.2)
    time.sleep(2.0)
    with score.lock:
        score.settle()
        score.recording = False
    result = {"restarts": reps, "cells": n_cells,
              "cell_seconds_unflagged_over_6_mm": score.bad_cell_s,
              "unflagged_worst_mm": 1e3 * score.worst_m,
              "unflagged_rms_mm": 1e3 * math.sqrt(score.sum_sq / score.n) if score.n else None}
    print("%d restarts: every cell flagged in %d, back in %d; unflagged worst %.2f mm, %.2f cell-seconds over 6 mm" % (
        len(reps), sum(r["flagged"] == n_cells for r in reps), sum(r["back"] == n_cells for r in reps),
        result["unflagged_worst_mm"], score.bad_cell_s))
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=10)
    parser.add_argument("--silence-s", type=float, default=1.0, help="the terminals' silence [s]")
    parser.add_argument("--flag-s", type=float, default=2.0, help="a cell must be flagged this soon after [s]")
    parser.add_argument("--back-s", type=float, default=60.0, help="and back on its target this soon [s]")
    parser.add_argument("--every-s", type=float, default=75.0, help="a restart this often, from one to the next [s]")
    add_bed_arguments(parser)
    args, launch_args = parser.parse_known_args()
    for name in ("silence_s", "flag_s", "back_s", "every_s"):
        if not (getattr(args, name) > 0.0 and math.isfinite(getattr(args, name))):
            parser.error("--%s must be a finite number > 0" % name.replace("_", "-"))
    if args.every_s < args.silence_s + args.back_s:
        parser.error("--every-s must be at least --silence-s + --back-s (a restart measured to its end)")
    if args.repeat < 1:
        parser.error("--repeat must be >= 1")
    with emulated_bed(args, launch_args, "restart_check", 30.0) as score:
        result = run(args, score, args.rows * args.cols)
        result.update({"rows": args.rows, "cols": args.cols, "launch_args": launch_args})
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
