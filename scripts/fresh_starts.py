#!/usr/bin/python3
"""Fresh starts of the bed, each judged from its first state (doc/safety.md, "Fresh starts").

Starts `roslaunch nursing_bed sim.launch` (or `real_bed.launch emulator:=true` with --real) --repeat
times, each in a process of its own (a new ROS master every time), and for each start:
  - watches /bed_manager/state for --watch-s after the first state: every plan it reports, the
    cells ever declared dead, faulty or unverified;
  - then reads every cell's height (/bed_manager/heights): the largest distance from the flat
    height (--flat-m);
  - then asks /bed_manager/set_airbag_height for --cell at --height-m and --settle-s later reads
    that cell's reported height and, on the emulator, its true height (/rig_emulator/truth).
A start passes when its plan was flat throughout, no cell was ever dead, every cell ended within
--flat-tolerance-m of the flat height, and the cell asked for (estimate, and truth where there is
one) ended within --cell-tolerance-m of --height-m with the estimate within that of the truth.
Prints one line a start and a summary; --json writes every start's figures. Exit code 0 when every
start passed, 1 otherwise, 2 for a bad command line.

usage: fresh_starts.py [--real] [--repeat N] [--watch-s S] [--json FILE] [launch args...]
e.g.   fresh_starts.py --repeat 20
       fresh_starts.py --real --repeat 10 --json /tmp/real_starts.json
"""
import argparse
import json
import math
import subprocess
import sys
import time

FLAT_PLAN = "flat"


def one_start(args, launch_args):
    """One launch, judged; returns its figures as a dict (raises RuntimeError when it never came up)."""
    import rospy
    from roslaunch_session import launched
    from nursing_bed.msg import BedHeights, BedState, RigTruth
    from nursing_bed.srv import SetHeight

    launch = ["roslaunch", "nursing_bed"]
    launch += ["real_bed.launch", "emulator:=true"] if args.real else ["sim.launch"]
    seen = {"plans": set(), "dead": set(), "faulty": set(), "unverified": set(), "first_state_s": None}
    last = {"heights": None, "truth": None}
    with launched(launch + launch_args):
        t_launch = time.monotonic()
        time.sleep(3.0)
        rospy.init_node("fresh_starts", anonymous=True, disable_signals=True)

        def on_state(msg):
            if seen["first_state_s"] is None:
                seen["first_state_s"] = time.monotonic() - t_launch
            seen["plans"].add(msg.plan)
            seen["dead"].update(msg.dead_cells)
            seen["faulty"].update(msg.faulty_cells)
            seen["unverified"].update(msg.unverified_cells)

        subs = [rospy.Subscriber("/bed_manager/state", BedState, on_state, queue_size=20),
                rospy.Subscriber("/bed_manager/heights", BedHeights, lambda m: last.update(heights=m), queue_size=2),
                rospy.Subscriber("/rig_emulator/truth", RigTruth, lambda m: last.update(truth=m), queue_size=2)]
        while seen["first_state_s"] is None:
            if time.monotonic() - t_launch > args.startup_timeout:
                raise RuntimeError("no /bed_manager/state within %.0f s of the launch" % args.startup_timeout)
            time.sleep(0.2)
        time.sleep(args.watch_s)
        heights = list(last["heights"].height_m) if last["heights"] else []
        flat_error = max((abs(h - args.flat_m) for h in heights), default=math.inf)
        flat_error = flat_error if all(math.isfinite(h) for h in heights) else math.inf
        watched = {k: sorted(seen[k]) for k in ("plans", "dead", "faulty", "unverified")}
        rospy.wait_for_service("/bed_manager/set_airbag_height", timeout=10.0)
        reply = rospy.ServiceProxy("/bed_manager/set_airbag_height", SetHeight)(args.cell, args.height_m)
        time.sleep(args.settle_s)
        estimate = last["heights"].height_m[args.cell] if last["heights"] else math.nan
        truth = last["truth"].height_m[args.cell] if last["truth"] else math.nan
        for s in subs:
            s.unregister()
    return {"first_state_s": seen["first_state_s"], "flat_error_m": flat_error, "cell_request_ok": reply.success,
            "cell_estimate_m": estimate, "cell_truth_m": truth, **watched}


def judged(args, r):
    """The reasons a start failed (empty: it passed)."""
    why = []
    if r["plans"] != [FLAT_PLAN]:
        why.append("plans %s" % r["plans"])
    if r["dead"]:
        why.append("dead cells %s" % r["dead"])
    if not r["flat_error_m"] <= args.flat_tolerance_m:
        why.append("a cell %.1f mm off flat" % (1e3 * r["flat_error_m"]))
    if not r["cell_request_ok"]:
        why.append("set_airbag_height refused")
    if not abs(r["cell_estimate_m"] - args.height_m) <= args.cell_tolerance_m:
        why.append("cell %d reports %.1f mm" % (args.cell, 1e3 * r["cell_estimate_m"]))
    if args.real and not abs(r["cell_estimate_m"] - r["cell_truth_m"]) <= args.cell_tolerance_m:
        why.append("cell %d estimate %.1f mm, truth %.1f mm" % (args.cell, 1e3 * r["cell_estimate_m"],
                                                               1e3 * r["cell_truth_m"]))
    return why


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--real", action="store_true", help="real_bed.launch emulator:=true instead of sim.launch")
    parser.add_argument("--repeat", type=int, default=1, help="fresh starts, each with its own ROS master, >= 1")
    parser.add_argument("--watch-s", type=float, default=60.0, help="watched after the first state, > 0 [s]")
    parser.add_argument("--flat-m", type=float, default=0.10, help="the flat plan's height [m]")
    parser.add_argument("--flat-tolerance-m", type=float, default=0.005, help="every cell this close to flat [m]")
    parser.add_argument("--cell", type=int, default=1, help="the cell asked for --height-m (row * cols + col)")
    parser.add_argument("--height-m", type=float, default=0.10, help="its requested height [m]")
    parser.add_argument("--cell-tolerance-m", type=float, default=0.002, help="the cell this close, to both [m]")
    parser.add_argument("--settle-s", type=float, default=40.0, help="read the cell this long after asking [s]")
    parser.add_argument("--startup-timeout", type=float, default=300.0, help="first state within this [s]")
    parser.add_argument("--json", default="", help="write every start's figures here")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # a child: one start, JSON out
    args, launch_args = parser.parse_known_args()
    if args.repeat < 1 or args.watch_s <= 0 or args.settle_s <= 0 or args.cell < 0:
        parser.error("--repeat >= 1, --watch-s > 0, --settle-s > 0 and --cell >= 0 are required")
    if args.one:
        print(json.dumps(one_start(args, launch_args)))
        return 0
    results, failed = [], 0
    for k in range(args.repeat):
        child = subprocess.run([sys.executable, __file__, "--one"] + sys.argv[1:], capture_output=True, text=True)
        lines = child.stdout.strip().splitlines()
        r = json.loads(lines[-1]) if child.returncode == 0 and lines else {"error": child.stderr.strip()[-400:]}
        why = judged(args, r) if "error" not in r else ["did not come up: " + r["error"]]
        r["failed"] = why
        failed += bool(why)
        results.append(r)
        print("start %d: %s (first state %.1f s)" % (k + 1, "; ".join(why) or "passed",
                                                    r.get("first_state_s") or math.nan), flush=True)
    print("%d of %d starts passed" % (args.repeat - failed, args.repeat))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
