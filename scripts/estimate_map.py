#!/usr/bin/python3
"""Where the running emulated bed's estimates stand against the rig emulator's truth, cell by cell
(doc/real_bed.md, "Estimate map").

Attaches to a running `real_bed.launch emulator:=true` (ROS_MASTER_URI as the bed's), listens
--listen-s to every cell's `~state` and to /rig_emulator/truth, and prints one rows x cols map
each (head end first) of: the estimated height minus the truth [mm], the truth [mm], the
estimate's sd [mm], the gas counted against the truth [%], the load the observer estimates and
the emulator's true load [N]; then the cells whose estimate is more than --limit-mm off while
the cell says it is verified. --json keeps the maps. Exit code 0 when every cell and the truth
were heard, 1 when not (or no master), 2 for a bad command line. Listening costs the bed a
little: on a machine already loaded (a parallel build beside the bed) a cell's state can come
late enough to be judged dead.

usage: estimate_map.py [--rows 20] [--cols 9] [--listen-s 5] [--limit-mm 6] [--json FILE]
"""
import argparse
import json
import math
import sys
import time


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=int, default=20, help="cell rows of the bed (default 20)")
    p.add_argument("--cols", type=int, default=9, help="cell columns of the bed (default 9)")
    p.add_argument("--listen-s", type=float, default=5.0, help="listen this long [s] (default 5)")
    p.add_argument("--limit-mm", type=float, default=6.0, help="list verified cells further off than this [mm]")
    p.add_argument("--json", help="write the maps here")
    a = p.parse_args(argv)
    if not (1 <= a.rows <= 200 and 1 <= a.cols <= 200):
        p.error("--rows and --cols must lie in [1, 200]")
    if not (math.isfinite(a.listen_s) and 0.5 <= a.listen_s <= 600.0):
        p.error("--listen-s must lie in [0.5, 600]")
    if not (math.isfinite(a.limit_mm) and a.limit_mm > 0.0):
        p.error("--limit-mm must be a positive number")
    return a


def listen(args):
    """The last state of every cell heard and the last truth, after --listen-s."""
    import rosgraph
    import rospy
    from nursing_bed.msg import AirbagState, RigTruth
    if not rosgraph.is_master_online():
        raise RuntimeError("no ROS master at %s" % rosgraph.get_master_uri())
    rospy.init_node("estimate_map", anonymous=True, disable_signals=True)
    states, truth = {}, {}

    def on_state(msg, cell):
        states[cell] = msg

    subs = [rospy.Subscriber("/airbag_%d_%d/state" % (r, c), AirbagState, on_state, callback_args=r * args.cols + c,
                             queue_size=1) for r in range(args.rows) for c in range(args.cols)]
    subs.append(rospy.Subscriber("/rig_emulator/truth", RigTruth, lambda m: truth.update(last=m), queue_size=1))
    time.sleep(args.listen_s)
    for s in subs:
        s.unregister()
    return states, truth.get("last")


def maps(args, states, truth):
    """Per cell (by id): the figures the maps print; NaN where a cell or the truth is missing."""
    nan = math.nan
    out = {k: [nan] * (args.rows * args.cols) for k in
           ("error_mm", "truth_mm", "sd_mm", "gas_error_pct", "load_n", "true_load_n")}
    for cell, s in states.items():
        if cell >= len(truth.height_m):
            continue
        out["error_mm"][cell] = 1e3 * (s.height_m - truth.height_m[cell])
        out["truth_mm"][cell] = 1e3 * truth.height_m[cell]
        out["sd_mm"][cell] = 1e3 * s.height_sd_m
        if truth.gas_mass_kg[cell] > 0.0:
            out["gas_error_pct"][cell] = 100.0 * (s.gas_mass_kg / truth.gas_mass_kg[cell] - 1.0)
        out["load_n"][cell] = s.external_load_n
        out["true_load_n"][cell] = truth.load_n[cell]
    return out


def print_map(title, values, cols, fmt):
    print(title)
    for r in range(len(values) // cols):
        print("  " + " ".join(fmt % v for v in values[r * cols:(r + 1) * cols]))


def main():
    args = parse_args(sys.argv[1:])
    try:
        states, truth = listen(args)
    except RuntimeError as e:
        print("estimate_map: %s" % e, file=sys.stderr)
        return 1
    if truth is None or len(states) < args.rows * args.cols:
        print("estimate_map: heard %d of %d cells and %s truth within %g s" % (
            len(states), args.rows * args.cols, "the" if truth else "no", args.listen_s), file=sys.stderr)
        return 1
    m = maps(args, states, truth)
    for key, title, fmt in (("error_mm", "estimate - truth [mm]", "%6.1f"), ("truth_mm", "truth [mm]", "%6.0f"),
                            ("sd_mm", "estimate sd [mm]", "%6.1f"), ("gas_error_pct", "gas counted - truth [%]", "%6.1f"),
                            ("load_n", "estimated load [N]", "%6.1f"), ("true_load_n", "true load [N]", "%6.1f")):
        print_map(title, m[key], args.cols, fmt)
    off = [(cell, e) for cell, e in enumerate(m["error_mm"])
           if abs(e) > args.limit_mm and not states[cell].height_unverified and not states[cell].faults]
    errors = [e for e in m["error_mm"] if math.isfinite(e)]
    print("RMS %.2f mm, worst %.1f mm; %d verified cell(s) more than %g mm off%s" % (
        math.sqrt(sum(e * e for e in errors) / len(errors)), max(errors, key=abs), len(off), args.limit_mm,
        ": " + ", ".join("%d_%d %+.1f" % (c // args.cols, c % args.cols, e) for c, e in off) if off else ""))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(m, rows=args.rows, cols=args.cols), f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
