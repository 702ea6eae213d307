#!/usr/bin/python3
"""Soak of the real-bed path under injected faults, scored against the rig emulator's truth
(doc/real_bed.md, "Soak").

Starts `roslaunch nursing_bed real_bed.launch emulator:=true` (rows x cols; a bed other than the
shipped 20 x 9 gets a one-terminal register map of its size), then for --minutes runs plans in
turn, an alternating 1-in-3 and a lateral turn, and every --fault-every-s injects a random fault
(stuck-open or stuck-shut inlet or vent, frozen sensor, +2 kPa offset, 5e-8 m^2 leak, 50 %
dropped replies) on --fault-cells random cells through /rig_emulator/inject_fault, cleared
--fault-hold-s later. Scored at every reported height (/bed_manager/heights, each cell's last
state with its own stamp) against the truth (/rig_emulator/truth, interpolated at that stamp):
either the estimate is within 6 mm of the truth or the cell is flagged (faulty or unverified in
/bed_manager/state within --flag-slack-s of the stamp). Prints and writes (--json):
  - cell-seconds with an unflagged error over 6 mm, RMS and worst of the unflagged error;
  - per fault kind: time from injection to the cell's first flag (and the cells never flagged);
    a valve stuck shut from the first move the plan asked of it (its target 1 mm up for an
    inlet, down for a vent; a cell only held meanwhile is harmless, counted apart);
  - time from a fault's clearing to the cell unflagged again;
  - false flags: flags raised on a cell with no fault injected since --recover-s.

usage: soak.py [--minutes M] [--rows R] [--cols C] [--seed S] [--json FILE] [launch args...]
e.g.   soak.py --minutes 10 --rows 9 --cols 3
"""
import argparse
import bisect
import collections
import contextlib
import json
import math
import random
import statistics
import sys
import tempfile
import threading
import time

import rospy

from roslaunch_session import launched
from nursing_bed.msg import BedHeights, BedState, RigTruth
from nursing_bed.srv import InjectRigFault, SetPosture

PROMISE_M = 0.006  # an unflagged estimate is within this of the truth
FAULTS = [  # (name, fault, valve, value)
    ("stuck-open inlet", "stuck_open", "inlet", 0.0),
    ("stuck-open vent", "stuck_open", "vent", 0.0),
    ("stuck-shut inlet", "stuck_closed", "inlet", 0.0),
    ("stuck-shut vent", "stuck_closed", "vent", 0.0),
    ("frozen sensor", "frozen_sensor", "", 0.0),
    ("offset +2 kPa", "sensor_offset", "", 2000.0),
    ("leak 5e-8 m2", "leak", "", 5e-8),
    ("50 % dropped replies", "drop_replies", "", 0.5),
]


def fault_key(fault):
    """A fault kind's name for --faults: the emulator's fault, with its valve where it has one."""
    return fault[1] + (":" + fault[2] if fault[2] else "")


def small_map(rows, cols, port):
    """A one-terminal register map of rows x cols cells, laid out as the shipped map's blocks."""
    n = rows * cols
    text = """terminals:
  - name: bed
    host: 127.0.0.1
    port: %d
    unit_id: 1
    response_timeout_s: 0.05
    link_loss_after_s: 0.2
    reconnect_interval_s: 0.25
    watchdog_s: 0.1
    cycle_s: 0.005
    stale_after_s: 0.2
    realtime_priority: 20
    supply_pressure: {input_register: 1000, scale_pa: 1.0, offset_pa: -10000.0}
    cell_block: {first_cell: 0, count: %d, valves: coil, inlet_start: 0, vent_start: %d, pressure_start: 0,
                 pressure_scale_pa: 1.0, pressure_offset_pa: -10000.0}
""" % (port, n, max(100, n))
    f = tempfile.NamedTemporaryFile("w", suffix=".yaml", prefix="soak_map_", delete=False)
    f.write(text)
    f.close()
    return f.name


class Score:
    """Reported heights against the truth, each at its own stamp, with the flags around it."""

    def __init__(self, slack_s):
        self.slack_s = slack_s
        self.truth = collections.deque(maxlen=400)  # (stamp, heights by cell)
        self.flags = collections.deque(maxlen=4000)  # (stamp, set of flagged cells)
        self.pending = collections.deque()  # (stamp, cell, height)
        self.last_stamp = {}
        self.sum_sq, self.n, self.worst_m, self.bad_cell_s = 0.0, 0, 0.0, 0.0
        self.worst_at, self.bad_by_cell = (None, None), {}  # (cell, stamp); cell-seconds over 6 mm
        self.flag_onsets = []  # (stamp, cell)
        self.target_moves = collections.defaultdict(list)  # cell -> [(stamp, target)] where it moved
        self.flagged_now = set()
        self.recording = False
        self.t0 = 0.0
        self.lock = threading.Lock()  # the subscribers' threads share the deques
        self.trace, self.traced_at = None, {}  # --trace: (file, each cell's last traced stamp)
        self.subs = [rospy.Subscriber("/rig_emulator/truth", RigTruth, self.on_truth, queue_size=50),
                     rospy.Subscriber("/bed_manager/heights", BedHeights, self.on_heights, queue_size=50),
                     rospy.Subscriber("/bed_manager/state", BedState, self.on_state, queue_size=50)]

    def on_state(self, msg):
        flagged = set(msg.faulty_cells) | set(msg.unverified_cells)
        t = msg.header.stamp.to_sec()
        with self.lock:
            if self.recording:
                self.flag_onsets += [(t, c) for c in flagged - self.flagged_now]
            self.flagged_now = flagged
            for cell, target in enumerate(msg.target_heights_m):
                moves = self.target_moves[cell]
                if not moves or abs(target - moves[-1][1]) > 2e-4:
                    moves.append((t, target))
            self.flags.append((t, flagged))

    def on_truth(self, msg):
        with self.lock:
            self.truth.append((msg.header.stamp.to_sec(), list(msg.height_m)))
            self.settle()

    def on_heights(self, msg):
        if not self.recording:
            return
        with self.lock:
            self.add_heights(msg)

    def add_heights(self, msg):
        for cell, (stamp, height) in enumerate(zip(msg.stamps, msg.height_m)):
            t = stamp.to_sec()
            if t > self.last_stamp.get(cell, 0.0) and math.isfinite(height):
                dt = min(0.5, t - self.last_stamp[cell]) if cell in self.last_stamp else 0.0
                self.last_stamp[cell] = t
                self.pending.append((t, cell, height, dt))

    def flagged(self, cell, t, flag_stamps):
        # Flagged in any bed state within the slack of the stamp (the manager reports at its rate).
        i = bisect.bisect_left(flag_stamps, t - self.slack_s)
        while i < len(flag_stamps) and flag_stamps[i] <= t + self.slack_s:
            if cell in self.flags[i][1]:
                return True
            i += 1
        return False

    def settle(self):
        if not self.truth or not self.flags:
            return
        stamps = [s[0] for s in self.truth]
        flag_stamps = [f[0] for f in self.flags]
        while self.pending and self.pending[0][0] <= stamps[-1] and self.pending[0][0] + self.slack_s <= self.flags[-1][0]:
            t, cell, height, dt = self.pending.popleft()
            i = bisect.bisect_left(stamps, t)
            if i == 0:
                continue
            (t0, h0), (t1, h1) = self.truth[i - 1], self.truth[i]
            if cell >= len(h0) or t1 <= t0:
                continue
            truth = h0[cell] + (t - t0) / (t1 - t0) * (h1[cell] - h0[cell])
            if not math.isfinite(truth):
                continue
            flagged = self.flagged(cell, t, flag_stamps)
            if self.trace and t - self.traced_at.get(cell, 0.0) >= 0.5:
                self.traced_at[cell] = t
                target = self.target_moves[cell][-1][1] if self.target_moves[cell] else math.nan
                self.trace.write("%.3f,%d,%.5f,%.5f,%.5f,%d\n" % (t - self.t0, cell, truth, height, target, flagged))
            if flagged:
                continue
            error = truth - height
            self.sum_sq += error * error
            self.n += 1
            if abs(error) > self.worst_m:
                self.worst_m, self.worst_at = abs(error), (cell, t)
            if abs(error) > PROMISE_M:
                self.bad_cell_s += dt
                self.bad_by_cell[cell] = self.bad_by_cell.get(cell, 0.0) + dt


def terminal_cells(cells, n_cells):
    """Every cell on the terminals serving `cells`: the shipped map's 60-cell terminals, else one."""
    if n_cells != 180:
        return list(range(n_cells))
    terminals = {c // 60 for c in cells}
    return [c for c in range(n_cells) if c // 60 in terminals]


def call_service(name, service_type, *request, wait_s=10.0):
    """The service's reply, or None with the reason printed: a bed manager that died is a finding
    of the soak (it respawns within seconds), not the end of it."""
    try:
        rospy.wait_for_service(name, timeout=wait_s)
        return rospy.ServiceProxy(name, service_type)(*request)
    except (rospy.ROSException, rospy.ServiceException) as e:
        print("soak: %s unavailable for %.0f s (%s): skipped" % (name, wait_s, e))
        return None


def call_posture(plan, keys, values):
    reply = call_service("/bed_manager/set_posture", SetPosture, plan, keys, values, [])
    if reply is not None and not reply.success:
        print("soak: %s refused: %s" % (plan, reply.message))


def inject(fault, cells, valve="", value=0.0):
    reply = call_service("/rig_emulator/inject_fault", InjectRigFault, fault, cells, 0, valve, value, 0.0, False)
    if reply is not None and not reply.success:
        print("soak: %s refused: %s" % (fault, reply.message))
    return reply is not None and reply.success


def summarise(score, injections, recoveries, wall_s, faulted_until):
    by_kind = collections.defaultdict(list)
    missed = collections.defaultdict(int)
    for name, cell, at, flag_s in injections:
        if flag_s is None:
            missed[name] += 1
        else:
            by_kind[name].append(flag_s)
    false_flags = [(t, c) for t, c in score.flag_onsets if t > faulted_until.get(c, -1.0)]
    result = {
        "seconds": wall_s, "samples": score.n,
        "unflagged_rms_mm": 1e3 * math.sqrt(score.sum_sq / score.n) if score.n else None,
        "unflagged_worst_mm": 1e3 * score.worst_m,
        "cell_seconds_unflagged_over_6_mm": score.bad_cell_s,
        "time_to_flag_s": {k: {"n": len(v), "median": statistics.median(v), "max": max(v)} for k, v in by_kind.items()},
        "never_flagged": dict(missed),
        "time_to_recover_s": {"n": len(recoveries), "median": statistics.median(recoveries) if recoveries else None,
                              "max": max(recoveries) if recoveries else None},
        "false_flags": len(false_flags),
        "unflagged_worst_cell_at": [score.worst_at[0], score.worst_at[1] - score.t0 if score.worst_at[1] else None],
        "cell_seconds_over_6_mm_by_cell": {str(c): v for c, v in sorted(score.bad_by_cell.items())},
        "false_flag_cells": sorted({c for _, c in false_flags}),
    }
    print("soak %.0f s, %d samples: unflagged RMS %s mm, worst %.2f mm, %.2f cell-seconds unflagged over 6 mm"
          % (wall_s, score.n, "%.2f" % result["unflagged_rms_mm"] if score.n else "-", result["unflagged_worst_mm"],
             score.bad_cell_s))
    for name in [f[0] + held for f in FAULTS for held in ("", ", held")]:
        if name in by_kind or name in missed:
            v = by_kind.get(name, [])
            print("  %-22s flagged %d (median %s s, max %s s), never flagged %d" % (
                name, len(v), "%.2f" % statistics.median(v) if v else "-", "%.2f" % max(v) if v else "-",
                missed.get(name, 0)))
    if recoveries:
        print("  recovery after clearing: median %.1f s, max %.1f s (%d cells)" % (
            statistics.median(recoveries), max(recoveries), len(recoveries)))
    print("  false flags (cells with no fault since the recovery time): %d on cells %s"
          % (len(false_flags), result["false_flag_cells"]))
    if score.worst_at[0] is not None:
        print("  worst unflagged: cell %d at %.0f s; cell-seconds over 6 mm by cell: %s" % (
            score.worst_at[0], score.worst_at[1] - score.t0,
            ", ".join("%d: %.1f" % (c, v) for c, v in sorted(score.bad_by_cell.items()))))
    return result


def first_command(score, cell, direction, since, until):
    """The first stamp in [since, until] at which the cell's target stood 1 mm `direction` (+1 up,
    -1 down) of where it stood at `since`; None when the plan never asked that."""
    with score.lock:
        moves = list(score.target_moves.get(cell, []))
    base = None
    for t, target in moves:
        if t <= since:
            base = target
        elif t <= until and base is not None and direction * (target - base) >= 1e-3:
            return t
    return None


def first_flag(score, cell, since, timeout_s):
    t_end = since + timeout_s
    with score.lock:
        onsets, flags = list(score.flag_onsets), list(score.flags)
    for t, c in onsets:
        if c == cell and since <= t <= t_end:
            return t - since
    for t, f in flags:
        if since <= t <= t_end and cell in f:
            return t - since
    return None


def judged_injection(score, name, cell, at, cleared, flag_within_s):
    """(name, cell, from, seconds to flag or None): a valve stuck shut is timed from the first move
    that needs it ("stuck-shut ..., held" when none came before `cleared`), the rest from `at`."""
    kind = next(f for f in FAULTS if f[0] == name)
    if kind[1] != "stuck_closed":
        return name, cell, at, first_flag(score, cell, at, flag_within_s)
    command = first_command(score, cell, +1 if kind[2] == "inlet" else -1, at, cleared)
    if command is None:
        return name + ", held", cell, at, first_flag(score, cell, at, flag_within_s)
    flag_s = first_flag(score, cell, at, command - at + flag_within_s)
    return name, cell, command, None if flag_s is None else max(0.0, flag_s - (command - at))


def run(args, score, n_cells):
    rng = random.Random(args.seed)
    kinds = [f for f in FAULTS if not args.faults or fault_key(f) in args.faults or f[1] in args.faults]
    plans = [("alternating", ["pattern", "period_s"], ["1in3", str(args.plan_s)]),
             ("lateral_turn", ["side", "angle_deg", "ramp_s", "dwell_s"], ["left", "20", "30", str(args.plan_s / 2)])]
    injections, recoveries, open_faults, faulted_until, n_faults = [], [], [], {}, 0
    t0 = rospy.get_time()
    next_plan, next_fault, plan_i = t0, (t0 + args.fault_every_s / 2) if args.fault_every_s > 0 else math.inf, 0
    score.recording = True
    score.t0 = t0
    while rospy.get_time() - t0 < 60.0 * args.minutes and not rospy.is_shutdown():
        now = rospy.get_time()
        if now >= next_plan:
            call_posture(*plans[plan_i % 2])
            plan_i += 1
            next_plan = now + args.plan_s
        if now >= next_fault:
            # Named kinds in turn (each seen), else drawn from all.
            name, fault, valve, value = kinds[n_faults % len(kinds)] if args.faults else rng.choice(kinds)
            n_faults += 1
            cells = sorted(rng.sample(range(n_cells), min(args.fault_cells, n_cells)))
            if inject(fault, cells, valve, value):
                open_faults.append((name, cells, now))
                # Dropped replies are the terminal's: every cell it serves is faulted.
                hit = terminal_cells(cells, n_cells) if fault == "drop_replies" else cells
                for c in hit:
                    faulted_until[c] = float("inf")
                print("soak: %.0f s: %s on cells %s" % (now - t0, name, cells))
            next_fault = now + rng.uniform(0.75, 1.25) * args.fault_every_s
        for name, cells, at in list(open_faults):
            if now - at >= args.fault_hold_s:
                inject("clear", cells)
                open_faults.remove((name, cells, at))
                for c in cells:
                    injections.append(judged_injection(score, name, c, at, now, args.flag_within_s))
                for c in terminal_cells(cells, n_cells) if name.endswith("dropped replies") else cells:
                    faulted_until[c] = now + args.recover_s
                recoveries += [(c, now) for c in cells]
        time.sleep(0.2)
    for name, cells, at in open_faults:
        inject("clear", cells)
        for c in cells:
            injections.append(judged_injection(score, name, c, at, rospy.get_time(), args.flag_within_s))
    with score.lock:
        score.recording = False
        flags = list(score.flags)
    # Recovery: from the clearing to the cell's first bed state without its flag.
    times = []
    for cell, cleared in recoveries:
        later = [t for t, f in flags if t >= cleared and cell not in f]
        if later:
            times.append(later[0] - cleared)
    return summarise(score, injections, times, rospy.get_time() - t0, faulted_until)


def add_bed_arguments(parser):
    """The emulated bed's arguments, shared with restart_check.py."""
    parser.add_argument("--rows", type=int, default=20)
    parser.add_argument("--cols", type=int, default=9)
    parser.add_argument("--flag-slack-s", type=float, default=0.25, help="a flag counts this close to a height's stamp")
    parser.add_argument("--startup-timeout", type=float, default=300.0)
    parser.add_argument("--port", type=int, default=15120, help="the small bed's Modbus TCP port (one free on this host)")
    parser.add_argument("--json", default="")
    parser.add_argument("--trace", default="", help="CSV of each cell's truth, estimate, target and flag every 0.5 s")


@contextlib.contextmanager
def emulated_bed(args, launch_args, node_name, settle_s):
    """real_bed.launch emulator:=true of args.rows x args.cols with launch_args, this process a
    node of it; waits for the bed's first state and the truth, then settle_s (the cells find their
    gas and the bed goes flat). Yields the Score, already listening."""
    extra = [] if (args.rows, args.cols) == (20, 9) else ["register_map:=" + small_map(args.rows, args.cols, args.port)]
    with launched(["roslaunch", "nursing_bed", "real_bed.launch", "emulator:=true", "rows:=%d" % args.rows,
                   "cols:=%d" % args.cols] + extra + launch_args):
        time.sleep(3.0)
        rospy.init_node(node_name, anonymous=True, disable_signals=True)
        score = Score(args.flag_slack_s)
        rospy.wait_for_service("/bed_manager/set_posture", timeout=args.startup_timeout)
        rospy.wait_for_service("/rig_emulator/inject_fault", timeout=args.startup_timeout)
        t0 = time.monotonic()
        while len(score.flags) == 0 or not score.truth:
            if time.monotonic() - t0 > args.startup_timeout:
                sys.exit("%s: no bed state or truth after %.0f s" % (node_name, args.startup_timeout))
            time.sleep(0.5)
        time.sleep(settle_s)
        yield score


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--plan-s", type=float, default=240.0, help="each plan runs this long (the alternating period)")
    parser.add_argument("--fault-every-s", type=float, default=120.0,
                        help="a fault about this often (+-25 %%); 0: none (the fault-free baseline)")
    parser.add_argument("--fault-cells", type=int, default=5)
    parser.add_argument("--faults", type=lambda s: s.split(","), default=[],
                        help="the fault kinds, in turn, comma-separated (e.g. leak,stuck_open:vent); default: all, drawn")
    parser.add_argument("--fault-hold-s", type=float, default=60.0, help="a fault is cleared after this long")
    parser.add_argument("--flag-within-s", type=float, default=30.0, help="a fault's flag counts this long after it")
    parser.add_argument("--recover-s", type=float, default=60.0, help="flags this long after a clearing are not false")
    add_bed_arguments(parser)
    args, launch_args = parser.parse_known_args()
    known = {fault_key(f) for f in FAULTS} | {f[1] for f in FAULTS}
    unknown = [k for k in args.faults if k not in known]
    if unknown:
        parser.error("--faults: unknown kind(s) %s; known: %s" % (", ".join(unknown), ", ".join(sorted(known))))
    with emulated_bed(args, launch_args, "soak", 20.0) as score, \
            open(args.trace or "/dev/null", "w") as trace:
        if args.trace:
            score.trace = trace
            trace.write("t_s,cell,truth_m,estimate_m,target_m,flagged\n")
        result = run(args, score, args.rows * args.cols)
        with score.lock:
            score.trace = None  # the truth's callbacks outlive the file
        result.update({"rows": args.rows, "cols": args.cols, "seed": args.seed, "launch_args": launch_args})
        if args.json:
            with open(args.json, "w") as f:
                json.dump(result, f, indent=2)


if __name__ == "__main__":
    main()
