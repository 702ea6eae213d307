#!/usr/bin/python3
"""Real-time benchmark of the whole simulated bed (doc/benchmarks.md).

Starts `roslaunch nursing_bed sim.launch` with the given args, waits until every cell publishes,
then for --seconds (default 60) counts each cell's AirbagState messages and the largest gap
between two of them, and samples CPU time and resident memory of every process of the launch.
It also checks that the cells' simulation keeps pace with wall time: a cell that fell behind
would publish late or rarely. Counting makes the launch serialise every cell's states for the
bench, so a second window of --alone-seconds (default --seconds) measures the CPU again with the
bench's subscriptions dropped: what the bed costs with no reader outside the launch. Prints a
table and writes --json FILE.

On the Modbus path (--launch real_bed.launch emulator:=true) --accuracy also compares every
cell's reported height (/bed_manager/heights: each cell's last state with its own stamp; the
observer's estimate where there is no height sensor) with the rig emulator's truth
(/rig_emulator/truth, stamped with the instant it describes, interpolated at the state's stamp)
over the window: RMS and worst error over all cells, the worst cell and when, the cells whose
worst exceeds 6 mm; and the same at /joint_states' publish stamps (the measure until 2026-11-25).
--plan starts a posture plan through /bed_manager/set_posture when the window opens
(--plan-arg key=value for its arguments, repeatable).

usage: bench_bed.py [--seconds S] [--json FILE] [--rows R] [--cols C] [--launch FILE]
                    [--accuracy] [--plan NAME [--plan-arg K=V ...]] [launch args...]
e.g.   bench_bed.py --seconds 60 use_nodelets:=true
       bench_bed.py --launch real_bed.launch --seconds 600 --accuracy --plan alternating \
           --plan-arg pattern=1in3 --plan-arg period_s=200 emulator:=true
"""
import argparse
import bisect
import collections
import json
import math
import re
import os
import sys
import time

import rospy

from roslaunch_session import launched


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


class ErrorTally:
    """Height error (truth - reported) per cell: RMS, worst (and when), mean."""

    def __init__(self):
        self.sum_sq, self.sum, self.count, self.worst, self.worst_at = {}, {}, {}, {}, {}

    def add(self, cell, error, at_s):
        self.sum_sq[cell] = self.sum_sq.get(cell, 0.0) + error * error
        self.sum[cell] = self.sum.get(cell, 0.0) + error
        self.count[cell] = self.count.get(cell, 0) + 1
        if abs(error) > self.worst.get(cell, -1.0):
            self.worst[cell], self.worst_at[cell] = abs(error), at_s

    def result(self, prefix):
        n = sum(self.count.values())
        if n == 0:
            return {prefix + "samples": 0}
        worst_cell = max(self.worst, key=self.worst.get)
        return {prefix + "rms_mm": 1e3 * math.sqrt(sum(self.sum_sq.values()) / n),
                prefix + "worst_mm": 1e3 * self.worst[worst_cell], prefix + "worst_cell": worst_cell,
                prefix + "worst_at_s": self.worst_at[worst_cell], prefix + "samples": n,
                prefix + "cells": len(self.count),
                prefix + "cells_over_6_mm": sum(1 for w in self.worst.values() if w > 6e-3)}

    def per_cell(self):
        """per cell: [RMS, worst, mean (truth - reported)] [mm], and when the worst was [s into the window]."""
        return {c: [1e3 * math.sqrt(self.sum_sq[c] / self.count[c]), 1e3 * self.worst[c],
                    1e3 * self.sum[c] / self.count[c], self.worst_at[c]] for c in sorted(self.count)}


class HeightAccuracy:
    """Reported heights against the rig emulator's truth, cell by cell, each at its own stamp.

    The primary measure takes every cell's states from /bed_manager/heights (each height with the
    stamp of the state it came from) and the truth (/rig_emulator/truth, stamped with the instant
    it describes) interpolated at that stamp; a sample waits until truth after its stamp has
    arrived. The /joint_states measure (the bench's until 2026-11-25) compares the same heights at
    the joint state's publish stamp, up to a state period newer than the heights it carries."""

    def __init__(self, cols):
        from sensor_msgs.msg import JointState
        from nursing_bed.msg import BedHeights, RigTruth
        self.cols = cols
        self.truth = collections.deque(maxlen=200)  # (stamp [s], heights by cell id)
        self.pending = collections.deque()  # (stamp [s], tally, [(cell, reported height)])
        self.own_stamp, self.joint_states = ErrorTally(), ErrorTally()
        self.last_stamp = {}  # per cell: the stamp last counted (a state repeated is counted once)
        self.window_start = None
        self.recording = False
        self.subs = [rospy.Subscriber("/rig_emulator/truth", RigTruth, self.on_truth, queue_size=20),
                     rospy.Subscriber("/bed_manager/heights", BedHeights, self.on_heights, queue_size=20),
                     rospy.Subscriber("/joint_states", JointState, self.on_joints, queue_size=20)]

    def start(self):
        self.window_start = rospy.get_time()
        self.recording = True

    def on_truth(self, msg):
        self.truth.append((msg.header.stamp.to_sec(), list(msg.height_m)))
        self.settle()

    def on_heights(self, msg):
        if not self.recording:
            return
        for cell, (stamp, height) in enumerate(zip(msg.stamps, msg.height_m)):
            t = stamp.to_sec()
            if t > self.last_stamp.get(cell, 0.0) and math.isfinite(height):
                self.last_stamp[cell] = t
                self.pending.append((t, self.own_stamp, [(cell, height)]))

    def on_joints(self, msg):
        if not self.recording:
            return
        cells = []
        for name, height in zip(msg.name, msg.position):
            m = re.search(r"(\d+)_(\d+)", name)
            if m:
                cells.append((int(m.group(1)) * self.cols + int(m.group(2)), height))
        self.pending.append((msg.header.stamp.to_sec(), self.joint_states, cells))

    def settle(self):
        """Compares the pending samples the truth now covers (truth stamped at or after theirs)."""
        if not self.truth:
            return
        stamps = [s[0] for s in self.truth]
        still = collections.deque()
        while self.pending:
            t, tally, cells = self.pending.popleft()
            if t > stamps[-1]:
                still.append((t, tally, cells))
                continue
            h0, h1, w = self.truth_around(stamps, t)
            for cell, height in cells:
                truth = h0[cell] + w * (h1[cell] - h0[cell]) if cell < len(h0) else float("nan")
                if math.isfinite(truth):
                    tally.add(cell, truth - height, t - self.window_start)
        self.pending = still

    def truth_around(self, stamps, t):
        """(h0, h1, w): the truth at t is h0 + w (h1 - h0), linear between the samples stamped
        before and after t (the emulator steps every 5 ms, its truth is published at 50 Hz);
        before the first, the first. Only the cells compared are interpolated (one a sample)."""
        i = bisect.bisect_left(stamps, t)
        if i == 0:
            return self.truth[0][1], self.truth[0][1], 0.0
        (t0, h0), (t1, h1) = self.truth[i - 1], self.truth[i]
        return h0, h1, (t - t0) / (t1 - t0) if t1 > t0 else 0.0

    def result(self):
        out = {"height_error_" + k: v for k, v in self.own_stamp.result("").items()}
        out.update(self.joint_states.result("joint_states_error_"))
        out["per_cell_mm"] = self.own_stamp.per_cell()
        return out


def start_plan(plan, plan_args):
    from nursing_bed.srv import SetPosture
    rospy.wait_for_service("/bed_manager/set_posture", timeout=30.0)
    keys, values = zip(*(a.split("=", 1) for a in plan_args)) if plan_args else ((), ())
    reply = rospy.ServiceProxy("/bed_manager/set_posture", SetPosture)(plan, list(keys), list(values), [])
    if not reply.success:
        sys.exit("bench_bed: plan %s refused: %s" % (plan, reply.message))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--json", default="")
    parser.add_argument("--rows", type=int, default=20)
    parser.add_argument("--cols", type=int, default=9)
    parser.add_argument("--startup-timeout", type=float, default=300.0)
    parser.add_argument("--launch", default="sim.launch", help="launch file of nursing_bed (real_bed.launch: the Modbus path)")
    parser.add_argument("--settle-s", type=float, default=0.0, help="wait this long after start-up before the window")
    parser.add_argument("--accuracy", action="store_true", help="reported heights against the rig emulator's truth")
    parser.add_argument("--plan", default="", help="posture plan started when the window opens")
    parser.add_argument("--plan-arg", action="append", default=[], help="key=value argument of --plan (repeatable)")
    parser.add_argument("--alone-seconds", type=float, default=None,
                        help="then this long (default --seconds; 0: skip) with the bench's subscriptions dropped: "
                             "the launch's CPU with no reader outside it")
    args, launch_args = parser.parse_known_args()
    bad = [a for a in args.plan_arg if "=" not in a]
    if bad:
        parser.error("--plan-arg wants key=value, got %s" % ", ".join(bad))
    n_cells = args.rows * args.cols

    with launched(["roslaunch", "nursing_bed", args.launch, "rows:=%d" % args.rows,
                   "cols:=%d" % args.cols] + launch_args) as launch:
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
        time.sleep(2.0 + args.settle_s)  # let connections (and with --settle-s the bed) settle
        accuracy = HeightAccuracy(args.cols) if args.accuracy else None
        if args.plan:
            start_plan(args.plan, args.plan_arg)
        if accuracy:
            accuracy.start()
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
        for s in subs + (accuracy.subs if accuracy else []):
            s.unregister()
        # Counting every cell's states makes the launch serialise and send 180 topics over TCP;
        # the same launch with no reader outside it is what the bed costs its users.
        alone_s = args.seconds if args.alone_seconds is None else args.alone_seconds
        cpu_alone = None
        if alone_s > 0:
            time.sleep(2.0)  # the dropped connections close
            cpu2, _ = cpu_and_rss(descendants(launch.pid))
            wall2 = time.monotonic()
            time.sleep(alone_s)
            cpu_alone = (cpu_and_rss(descendants(launch.pid))[0] - cpu2) / (time.monotonic() - wall2)
        rates = [counts.get(i, 0) / wall for i in range(n_cells)]
        result = {
            "launch_args": launch_args, "rows": args.rows, "cols": args.cols, "seconds": wall,
            "startup_s": startup_s, "processes": len(pids),
            "rate_hz_min": min(rates), "rate_hz_mean": sum(rates) / n_cells,
            "cells_below_45_hz": sum(1 for r in rates if r < 45.0),
            "max_gap_s": max(max_gap.values()) if max_gap else None,
            "cpu_cores_used": (cpu1 - cpu0) / wall,
            "cpu_cores_alone": cpu_alone,
            "rss_mb_mean": sum(rss_samples) / len(rss_samples) / 2**20,
        }
        if accuracy:
            result.update(accuracy.result())
        print("cells %d, %s: startup %.1f s, %d processes" % (n_cells, " ".join(launch_args) or "defaults",
                                                            startup_s, len(pids)))
        print("  AirbagState rate per cell: min %.1f Hz, mean %.1f Hz, %d cells below 45 Hz, largest gap %.3f s"
              % (result["rate_hz_min"], result["rate_hz_mean"], result["cells_below_45_hz"], result["max_gap_s"]))
        print("  CPU %.2f cores (of %d) while counted, resident memory %.0f MB" % (
            result["cpu_cores_used"], os.cpu_count(), result["rss_mb_mean"]))
        if cpu_alone is not None:
            print("  CPU %.2f cores with no reader outside the launch (%.0f s after)" % (cpu_alone, alone_s))
        if accuracy and result.get("height_error_samples"):
            print("  reported height vs truth at each state's stamp: RMS %.2f mm, worst %.2f mm (cell %d at %.1f s), "
                  "%d cells over 6 mm, %d cells, %d samples"
                  % (result["height_error_rms_mm"], result["height_error_worst_mm"], result["height_error_worst_cell"],
                     result["height_error_worst_at_s"], result["height_error_cells_over_6_mm"],
                     result["height_error_cells"], result["height_error_samples"]))
            if result.get("joint_states_error_samples"):
                print("  the same at /joint_states' publish stamps: RMS %.2f mm, worst %.2f mm (cell %d), %d cells over 6 mm"
                      % (result["joint_states_error_rms_mm"], result["joint_states_error_worst_mm"],
                         result["joint_states_error_worst_cell"], result["joint_states_error_cells_over_6_mm"]))
        elif accuracy:
            print("  reported height vs truth: no samples (are /rig_emulator/truth and /bed_manager/heights published?)")
        if args.json:
            with open(args.json, "w") as f:
                json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
