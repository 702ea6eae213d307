#!/usr/bin/python3
"""A whole bed overloaded and released (doc/safety.md, "Overload of every cell").

Starts `roslaunch nursing_bed sim.launch simulator:=false` (every cell under --load-n), waits
--warmup-s for the flat bed, then puts --overload-n on every cell through /airbag_loads for
--overload-s and the normal load back, --repeat times with --rest-s between. After each release
it measures the time until every cell reports within --tolerance-m of its target with no fault
(/bed_manager/state and /bed_manager/heights), up to --limit-s. Prints one line an overload and a
summary; --json writes the figures. Exit code 0 when every release recovered within --limit-s.

usage: overload_check.py [--repeat N] [--overload-n F] [--json FILE] [launch args...]
"""
import argparse
import json
import math
import sys
import time


def recovered(state, heights, tolerance_m):
    """Every cell within tolerance of its target (where it has one) and none faulty or dead."""
    if state is None or heights is None or state.faulty_cells or state.dead_cells:
        return False
    pairs = [(h, t) for h, t in zip(heights.height_m, state.target_heights_m) if math.isfinite(t)]
    return bool(pairs) and all(abs(h - t) <= tolerance_m for h, t in pairs)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeat", type=int, default=3, help="overloads, >= 1")
    parser.add_argument("--load-n", type=float, default=10.6, help="every cell's normal load [N]")
    parser.add_argument("--overload-n", type=float, default=999.0, help="every cell's load while overloaded [N]")
    parser.add_argument("--overload-s", type=float, default=1.0, help="how long, > 0 [s]")
    parser.add_argument("--warmup-s", type=float, default=60.0, help="before the first overload [s]")
    parser.add_argument("--rest-s", type=float, default=10.0, help="after a recovery, before the next overload [s]")
    parser.add_argument("--tolerance-m", type=float, default=0.002, help="a cell this close to its target [m]")
    parser.add_argument("--limit-s", type=float, default=30.0, help="a release must recover within this [s]")
    parser.add_argument("--json", default="")
    args, launch_args = parser.parse_known_args()
    if args.repeat < 1 or args.overload_s <= 0 or args.limit_s <= 0 or args.tolerance_m <= 0:
        parser.error("--repeat >= 1 and --overload-s, --limit-s, --tolerance-m > 0 are required")

    import rospy
    from roslaunch_session import launched
    from std_msgs.msg import Float64MultiArray
    from nursing_bed.msg import BedHeights, BedState

    last = {"state": None, "heights": None}
    results = []
    with launched(["roslaunch", "nursing_bed", "sim.launch", "simulator:=false", "load_n:=%g" % args.load_n]
                  + launch_args):
        time.sleep(3.0)
        rospy.init_node("overload_check", anonymous=True, disable_signals=True)
        rospy.Subscriber("/bed_manager/state", BedState, lambda m: last.update(state=m), queue_size=2)
        rospy.Subscriber("/bed_manager/heights", BedHeights, lambda m: last.update(heights=m), queue_size=2)
        loads = rospy.Publisher("/airbag_loads", Float64MultiArray, queue_size=2, latch=True)
        t0 = time.monotonic()
        while last["heights"] is None and time.monotonic() - t0 < 300.0:
            time.sleep(0.2)
        if last["heights"] is None:
            sys.exit("overload_check: no /bed_manager/heights within 300 s")
        n = len(last["heights"].height_m)
        time.sleep(args.warmup_s)
        for k in range(args.repeat):
            was_ready = recovered(last["state"], last["heights"], args.tolerance_m)
            loads.publish(Float64MultiArray(data=[args.overload_n] * n))
            time.sleep(args.overload_s)
            loads.publish(Float64MultiArray(data=[args.load_n] * n))
            t_release = time.monotonic()
            lowest = math.inf
            while time.monotonic() - t_release < args.limit_s:
                lowest = min([lowest] + list(last["heights"].height_m))
                if recovered(last["state"], last["heights"], args.tolerance_m):
                    break
                time.sleep(0.05)
            back_s = time.monotonic() - t_release
            ok = recovered(last["state"], last["heights"], args.tolerance_m)
            results.append({"ready_before": was_ready, "recovered": ok, "back_after_s": back_s if ok else None,
                            "lowest_reported_m": lowest})
            print("overload %d: %s (lowest reported %.1f mm)" % (
                k + 1, "back after %.1f s" % back_s if ok else "not back within %.0f s" % args.limit_s,
                1e3 * lowest), flush=True)
            time.sleep(args.rest_s)
    good = sum(r["recovered"] for r in results)
    print("%d of %d overloads recovered within %.0f s" % (good, len(results), args.limit_s))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0 if good == len(results) else 1


if __name__ == "__main__":
    sys.exit(main())
