#!/usr/bin/python3
"""Real-time benchmark of the whole simulated bed (doc/benchmarks.md).

Starts `roslaunch nursing_bed sim.launch` with the given args, waits until every cell publishes,
then for --seconds (default 60) counts each cell's AirbagState messages and the largest gap
between two of them, and samples CPU time and resident memory of every process of the launch.
It also checks that the cells' simulation keeps pace with wall time: a cell that fell behind
would publish late or rarely. Prints a table and writes --json FILE.

usage: bench_bed.py [--seconds S] [--json FILE] [--rows R] [--cols C] [launch args...]
e.g.   bench_bed.py --seconds 60 use_nodelets:=true
"""
import argparse
import json
import os
import signal
import subprocess
import sys
import time

import rospy


def descendants(pid):
    """pid and all its descendants (from /proc)."""
    children = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open("/proc/%s/stat" % entry) as f:
                fields = f.read().rsplit(")", 1)[1].split()
            children.setdefault(int(fields[1]), []).append(int(entry))
        except (OSError, IndexError):
            pass
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        todo.extend(children.get(p, []))
    return out


def cpu_and_rss(pids):
    """Total CPU seconds (user+system) and resident memory [bytes] of the given processes."""
    tick = os.sysconf("SC_CLK_TCK")
    page = os.sysconf("SC_PAGE_SIZE")
    cpu, rss = 0.0, 0
    for p in pids:
        try:
            with open("/proc/%d/stat" % p) as f:
                fields = f.read().rsplit(")", 1)[1].split()
            cpu += (int(fields[11]) + int(fields[12])) / tick
            rss += int(fields[21]) * page
        except (OSError, IndexError):
            pass
    return cpu, rss


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--json", default="")
    parser.add_argument("--rows", type=int, default=20)
    parser.add_argument("--cols", type=int, default=9)
    parser.add_argument("--startup-timeout", type=float, default=300.0)
    args, launch_args = parser.parse_known_args()
    n_cells = args.rows * args.cols

    launch = subprocess.Popen(["roslaunch", "nursing_bed", "sim.launch", "rows:=%d" % args.rows,
                               "cols:=%d" % args.cols] + launch_args,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, preexec_fn=os.setsid)
    try:
        time.sleep(3.0)
        rospy.init_node("bench_bed", anonymous=True, disable_signals=True)
        counts, last, max_gap = {}, {}, {}

        def on_state(msg, cell):
            now = time.monotonic()
            counts[cell] = counts.get(cell, 0) + 1
            if cell in last:
                max_gap[cell] = max(max_gap.get(cell, 0.0), now - last[cell])
            last[cell] = now

        # AnyMsg: count without deserialising, so the benchmark itself costs little CPU.
        subs = [rospy.Subscriber("/airbag_%d_%d/state" % (r, c), rospy.AnyMsg, on_state, callback_args=r * args.cols + c,
                                 queue_size=50) for r in range(args.rows) for c in range(args.cols)]
        t0 = time.monotonic()
        while len(counts) < n_cells:
            if time.monotonic() - t0 > args.startup_timeout:
                sys.exit("bench_bed: only %d of %d cells publish after %.0f s" % (len(counts), n_cells, args.startup_timeout))
            time.sleep(0.5)
        startup_s = time.monotonic() - t0
        time.sleep(2.0)  # let connections settle
        counts.clear()
        max_gap.clear()
        last.clear()
        pids = descendants(launch.pid)
        cpu0, _ = cpu_and_rss(pids)
        wall0 = time.monotonic()
        rss_samples = []
        while time.monotonic() - wall0 < args.seconds:
            time.sleep(1.0)
            rss_samples.append(cpu_and_rss(descendants(launch.pid))[1])
        wall = time.monotonic() - wall0
        cpu1, _ = cpu_and_rss(descendants(launch.pid))
        for s in subs:
            s.unregister()
        rates = [counts.get(i, 0) / wall for i in range(n_cells)]
        result = {
            "launch_args": launch_args, "rows": args.rows, "cols": args.cols, "seconds": wall,
            "startup_s": startup_s, "processes": len(pids),
            "rate_hz_min": min(rates), "rate_hz_mean": sum(rates) / n_cells,
            "cells_below_45_hz": sum(1 for r in rates if r < 45.0),
            "max_gap_s": max(max_gap.values()) if max_gap else None,
            "cpu_cores_used": (cpu1 - cpu0) / wall,
            "rss_mb_mean": sum(rss_samples) / len(rss_samples) / 2**20,
        }
        print("cells %d, %s: startup %.1f s, %d processes" % (n_cells, " ".join(launch_args) or "defaults",
                                                            startup_s, len(pids)))
        print("  AirbagState rate per cell: min %.1f Hz, mean %.1f Hz, %d cells below 45 Hz, largest gap %.3f s"
              % (result["rate_hz_min"], result["rate_hz_mean"], result["cells_below_45_hz"], result["max_gap_s"]))
        print("  CPU %.2f cores (of %d), resident memory %.0f MB" % (result["cpu_cores_used"], os.cpu_count(),
                                                                   result["rss_mb_mean"]))
        if args.json:
            with open(args.json, "w") as f:
                json.dump(result, f, indent=2)
    finally:
        os.killpg(os.getpgid(launch.pid), signal.SIGINT)
        try:
            launch.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(os.getpgid(launch.pid), signal.SIGKILL)


if __name__ == "__main__":
    main()
