#!/usr/bin/python3
"""The whole bed moved at once, scored against the rig emulator's truth (doc/real_bed.md,
"Soak").

Starts `roslaunch nursing_bed real_bed.launch emulator:=true` (rows x cols, as soak.py), waits
for the bed to settle, then asks the bed manager for `flat` at each height of --steps in turn
(every cell moving at once, as when a flagged cell levels the bed) and holds each for its time.
With --listen this process subscribes to every cell's state topic meanwhile, as a bag
recording them would: the cells' nodelet manager then serialises 50 states a second per cell
for it and its periods run late; --busy N adds N busy loops on the machine. Scored as soak.py scores (each reported height against the truth at its
stamp, unflagged beyond 6 mm counted); prints, after each step, the cell-seconds unflagged over
6 mm so far, the worst unflagged error and the cells flagged at its end; --json keeps them.

usage: raise_check.py [--steps H:S,H:S,...] [--listen] [--busy N] [--rows R] [--cols C] [launch args...]
e.g.   raise_check.py --steps 0.10:30,0.13:50 --listen --busy 2 simulator:=false load_n:=0.6
"""
import argparse
import contextlib
import json
import subprocess
import sys
import time

import rospy

from nursing_bed.msg import AirbagState
from soak import add_bed_arguments, call_posture, emulated_bed


def steps(text):
    """'0.10:30,0.13:50' -> [(0.10, 30.0), (0.13, 50.0)]."""
    out = []
    for item in text.split(","):
        try:
            height, hold = (float(x) for x in item.split(":"))
        except ValueError:
            raise argparse.ArgumentTypeError("'%s' is not HEIGHT_M:HOLD_S" % item) from None
        if not (0.0 <= height <= 0.2 and hold > 0.0):
            raise argparse.ArgumentTypeError("'%s': the height must lie in [0, 0.2] m, the hold above 0 s" % item)
        out.append((height, hold))
    return out


@contextlib.contextmanager
def busy_loops(n):
    loops = [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(n)]
    try:
        yield
    finally:
        for p in loops:
            p.kill()
            p.wait()


def listen_to_states(rows, cols):
    """Subscribes to every cell's state (and drops them): the load a bag recording them puts on
    the cells' nodelet manager."""
    return [rospy.Subscriber("/airbag_%d_%d/state" % (r, c), AirbagState, lambda _: None, queue_size=5)
            for r in range(rows) for c in range(cols)]


def hold_flat(score, height, hold):
    """Asks for flat at `height`, holds `hold` seconds; the score so far."""
    call_posture("flat", ["height_m"], [repr(height)])
    time.sleep(hold)
    with score.lock:
        r = {"height_m": height, "hold_s": hold, "bad_cell_s": score.bad_cell_s, "worst_m": score.worst_m,
             "flagged": len(score.flagged_now)}
    print("flat %.3f m for %.0f s: %.1f cell-seconds unflagged over 6 mm so far, worst %.1f mm, %d cells flagged"
          % (height, hold, r["bad_cell_s"], 1e3 * r["worst_m"], r["flagged"]))
    sys.stdout.flush()
    return r


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=steps, default=steps("0.10:30,0.13:50"),
                        help="flat heights [m] and their holds [s], in turn")
    parser.add_argument("--listen", action="store_true", help="subscribe to every cell's state while the steps run")
    parser.add_argument("--busy", type=int, default=0, help="busy loops on the machine while the steps run")
    add_bed_arguments(parser)
    args, launch_args = parser.parse_known_args()
    results = []
    with emulated_bed(args, launch_args, "raise_check", 20.0) as score, \
            open(args.trace or "/dev/null", "w") as trace:
        if args.trace:
            score.trace = trace
            trace.write("t_s,cell,truth_m,estimate_m,target_m,flagged\n")
        score.recording = True
        listeners = listen_to_states(args.rows, args.cols) if args.listen else []
        with busy_loops(args.busy):
            for height, hold in args.steps:
                results.append(hold_flat(score, height, hold))
        for s in listeners:
            s.unregister()
        with score.lock:
            score.trace = None  # the truth's callbacks outlive the file
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"steps": results, "listen": args.listen, "busy": args.busy, "launch_args": launch_args}, f, indent=2)


if __name__ == "__main__":
    main()
