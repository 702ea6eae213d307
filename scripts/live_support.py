#!/usr/bin/python3
"""A support plan on the running bed, scored with the patient simulator's tissue-load metrics
(doc/bed_study.md, "On the running bed").

Starts `roslaunch nursing_bed real_bed.launch emulator:=true` (or sim.launch with --sim) with the
articulated patient of --mass-kg and --height-m, waits for the bed's first state and --settle-s
on the flat bed, starts --plan through /bed_manager/set_posture (KEY=VALUE arguments after it),
waits --warmup-s, then measures --duration-s from /simulator/tissue_load as bed_study does: per
region the highest and the time-mean peak, the share of the time above the threshold, the dose
per hour, the lowest margin; the body's mean contact area; and whether any cell was dead,
faulty or unverified. With --compare FILE (a bed_study_support.json of the same plan and body)
it prints each figure's relative difference from the simulated one. --json writes the figures;
--trace writes a CSV, once a second of the measured window: the plan's elapsed time, its phase,
each region's peak [mmHg] and each cell's target height [m] (the columns of bed_study --trace).
--launch-arg passes NAME:=VALUE to roslaunch: with ROS_MASTER_URI on another port and
register_map:= a map on other Modbus ports, two beds run side by side. Exit code 0 when the run
was measured, 1 when the bed never came up or the plan was refused, 2 for a bad command line or
an unwritable --trace.

usage: live_support.py [--sim] [--plan adaptive] [--warmup-s S] [--duration-s S] [--json FILE]
                       [--trace CSV] [--compare FILE] [--launch-arg NAME:=VALUE ...] [KEY=VALUE ...]
e.g.   live_support.py --duration-s 7200 --json /tmp/live.json --compare doc/bed_study_support.json
"""
import argparse
import json
import math
import sys
import time

MMHG_PA = 133.322


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sim", action="store_true", help="sim.launch (height sensors) instead of the emulator")
    p.add_argument("--plan", default="adaptive", help="plan to start (default adaptive)")
    p.add_argument("--mass-kg", type=float, default=70.0)
    p.add_argument("--height-m", type=float, default=1.70)
    p.add_argument("--settle-s", type=float, default=15.0, help="on the flat bed before the plan [s]")
    p.add_argument("--warmup-s", type=float, default=120.0, help="under the plan before measuring [s]")
    p.add_argument("--duration-s", type=float, default=600.0, help="measured [s]")
    p.add_argument("--startup-timeout", type=float, default=120.0, help="wait this long for the first state [s]")
    p.add_argument("--json", help="write the figures here")
    p.add_argument("--trace", help="write a CSV of region peaks and cell targets, once a second")
    p.add_argument("--compare", help="bed_study_support.json of the same plan and body")
    p.add_argument("--launch-arg", action="append", default=[], metavar="NAME:=VALUE",
                   help="passed to roslaunch (repeatable), e.g. register_map:=FILE for a second bed on other ports")
    p.add_argument("plan_args", nargs="*", metavar="KEY=VALUE", help="the plan's arguments")
    a = p.parse_args(argv)
    for name in ("settle_s", "warmup_s", "duration_s", "startup_timeout"):
        if not getattr(a, name) >= 0.0 or not math.isfinite(getattr(a, name)):
            p.error("--%s must be a finite number >= 0" % name.replace("_", "-"))
    if not 20.0 <= a.mass_kg <= 250.0:
        p.error("--mass-kg must lie in [20, 250] (the patient simulator's range)")
    if not 1.0 <= a.height_m <= 2.3:
        p.error("--height-m must lie in [1.0, 2.3] (the patient simulator's range)")
    if not a.duration_s > 0.0:
        p.error("--duration-s must be positive")
    for kv in a.launch_arg:
        if ":=" not in kv or kv.startswith(":="):
            p.error("--launch-arg '%s' is not NAME:=VALUE" % kv)
    for kv in a.plan_args:
        if "=" not in kv or kv.startswith("="):
            p.error("plan argument '%s' is not KEY=VALUE" % kv)
    return a


class Meter:
    """Accumulates /simulator/tissue_load messages over the measured window."""

    def __init__(self):
        self.first = None
        self.last = None
        self.peak = {}
        self.peak_sum = {}
        self.margin = {}
        self.area_sum = 0.0
        self.samples = 0

    def add(self, msg):
        if self.first is None:
            self.first = msg
        self.last = msg
        for i, name in enumerate(msg.region):
            self.peak[name] = max(self.peak.get(name, 0.0), msg.peak_pressure_mmhg[i])
            self.peak_sum[name] = self.peak_sum.get(name, 0.0) + msg.peak_pressure_mmhg[i]
            if math.isfinite(msg.margin_m[i]):
                self.margin[name] = min(self.margin.get(name, math.inf), msg.margin_m[i])
        self.area_sum += msg.body_contact_area_m2
        self.samples += 1

    def figures(self):
        observed = self.last.observed_s - self.first.observed_s
        regions = {}
        for i, name in enumerate(self.last.region):
            above = self.last.time_above_threshold_s[i] - self.first.time_above_threshold_s[i]
            dose = self.last.dose[i] - self.first.dose[i]
            regions[name] = {"max_peak_mmhg": self.peak[name],
                             "mean_peak_mmhg": self.peak_sum[name] / self.samples,
                             "share_above_threshold": above / observed if observed > 0 else 0.0,
                             "dose_per_hour": dose * 3600.0 / observed if observed > 0 else 0.0,
                             "min_margin_mm": 1e3 * self.margin.get(name, math.nan)}
        return {"observed_s": observed, "contact_area_cm2": 1e4 * self.area_sum / max(1, self.samples),
                "regions": regions}


class Trace:
    """Once a second of the measured window: the plan's elapsed time and phase, each region's
    peak now [mmHg], each cell's target height [m]."""

    def __init__(self, file):
        self.file = file
        self.state = None
        self.last_s = -math.inf

    def add(self, tissue):
        # A new plan (safe_level after a dead cell, say) starts its elapsed time again.
        if self.file is None or self.state is None or abs(self.state.elapsed_s - self.last_s) < 1.0:
            return
        if self.last_s == -math.inf:
            self.file.write(",".join(["elapsed_s", "phase"] + ["peak_mmhg_" + r for r in tissue.region] +
                                     ["target_m_%d" % i for i in range(len(self.state.target_heights_m))]) + "\n")
        self.last_s = self.state.elapsed_s
        self.file.write(",".join(["%.2f" % self.state.elapsed_s, self.state.phase.replace(",", ";")] +
                                 ["%.2f" % v for v in tissue.peak_pressure_mmhg] +
                                 ["%.5f" % v for v in self.state.target_heights_m]) + "\n")

    def close(self):
        if self.file:
            self.file.close()


def measure(args, trace_file=None):
    import rospy
    from roslaunch_session import launched
    from nursing_bed.msg import BedState, TissueLoad
    from nursing_bed.srv import SetPosture

    launch = ["roslaunch", "nursing_bed", "sim.launch" if args.sim else "real_bed.launch"]
    if not args.sim:
        launch.append("emulator:=true")
    launch += ["patient_articulated:=true", "patient_mass_kg:=%g" % args.mass_kg, "patient_height_m:=%g" % args.height_m]
    launch += args.launch_arg
    flags = {"dead": set(), "faulty": set(), "unverified": set(), "plans": set(), "state": False}
    meter = Meter()
    trace = Trace(trace_file)
    recording = {"on": False}
    with launched(launch):
        time.sleep(3.0)
        rospy.init_node("live_support", anonymous=True, disable_signals=True)

        def on_state(msg):
            flags["state"] = True
            flags["plans"].add(msg.plan)
            trace.state = msg
            if recording["on"]:
                flags["dead"].update(msg.dead_cells)
                flags["faulty"].update(msg.faulty_cells)
                flags["unverified"].update(msg.unverified_cells)

        def on_tissue(msg):
            if recording["on"]:
                meter.add(msg)
                trace.add(msg)

        subs = [rospy.Subscriber("/bed_manager/state", BedState, on_state, queue_size=20),
                rospy.Subscriber("/simulator/tissue_load", TissueLoad, on_tissue, queue_size=20)]
        start = time.monotonic()
        while not flags["state"]:
            if time.monotonic() - start > args.startup_timeout:
                raise RuntimeError("no /bed_manager/state within %g s" % args.startup_timeout)
            time.sleep(0.2)
        time.sleep(args.settle_s)
        keys = [kv.split("=", 1)[0] for kv in args.plan_args]
        values = [kv.split("=", 1)[1] for kv in args.plan_args]
        rospy.wait_for_service("/bed_manager/set_posture", timeout=10.0)
        res = rospy.ServiceProxy("/bed_manager/set_posture", SetPosture)(args.plan, keys, values, [])
        if not res.success:
            raise RuntimeError("plan refused: " + res.message)
        time.sleep(args.warmup_s)
        recording["on"] = True
        time.sleep(args.duration_s)
        recording["on"] = False
        for s in subs:
            s.unregister()
        trace.close()
    if meter.samples < 2:
        raise RuntimeError("fewer than two /simulator/tissue_load messages in the measured window")
    out = meter.figures()
    out.update({"plan": args.plan, "plan_args": args.plan_args, "mass_kg": args.mass_kg, "height_m": args.height_m,
                "bed": "sim.launch" if args.sim else "real_bed.launch emulator:=true",
                "warmup_s": args.warmup_s, "duration_s": args.duration_s,
                "cells_dead": sorted(flags["dead"]), "cells_faulty": sorted(flags["faulty"]),
                "cells_unverified": sorted(flags["unverified"])})
    return out


def relative(live, simulated):
    if simulated == 0.0:
        return 0.0 if live == 0.0 else math.inf
    return (live - simulated) / abs(simulated)


def report(out, compare):
    sim = None
    if compare:
        with open(compare) as f:
            sim = json.load(f)["plans"][out["plan"]]
    print("%s, %s %g kg %g m, %.0f s measured: body contact area %.0f cm^2%s" % (
        out["bed"], out["plan"], out["mass_kg"], out["height_m"], out["observed_s"], out["contact_area_cm2"],
        " (simulated %.0f, %+.0f %%)" % (sim["contact_area_cm2"], 100 * relative(out["contact_area_cm2"],
                                                                            sim["contact_area_cm2"])) if sim else ""))
    print("cells dead %d faulty %d unverified %d" % (len(out["cells_dead"]), len(out["cells_faulty"]),
                                                     len(out["cells_unverified"])))
    print("  %-17s %14s %15s %10s %11s %14s" % ("region", "max peak mmHg", "mean peak mmHg", "share >32", "dose per h",
                                                "min margin mm"))
    for name, r in out["regions"].items():
        line = "  %-17s %14.1f %15.1f %9.0f%% %11.3f %14.1f" % (
            name, r["max_peak_mmhg"], r["mean_peak_mmhg"], 100 * r["share_above_threshold"], r["dose_per_hour"],
            r["min_margin_mm"])
        s = sim["regions"].get(name) if sim else None
        if s:
            line += "   simulated %.1f mmHg (%+.0f %%)" % (s["max_peak_mmhg"],
                                                       100 * relative(r["max_peak_mmhg"], s["max_peak_mmhg"]))
            if "mean_peak_mmhg" in s:
                line += ", mean %.1f (%+.0f %%)" % (s["mean_peak_mmhg"],
                                                  100 * relative(r["mean_peak_mmhg"], s["mean_peak_mmhg"]))
            line += ", %.0f%%, %.3f, %.1f mm" % (100 * s["share_above_threshold"], s["dose_per_hour"],
                                                s["min_margin_mm"])
        print(line)


def main():
    args = parse_args(sys.argv[1:])
    if args.compare:
        try:
            with open(args.compare) as f:
                plans = json.load(f)["plans"]
            if args.plan not in plans:
                raise KeyError("it has no plan '%s'" % args.plan)
        except (OSError, ValueError, KeyError) as e:
            print("live_support: --compare %s: %s" % (args.compare, e), file=sys.stderr)
            return 2
    try:
        trace_file = open(args.trace, "w") if args.trace else None
    except OSError as e:
        print("live_support: --trace %s: %s" % (args.trace, e.strerror), file=sys.stderr)
        return 2
    try:
        out = measure(args, trace_file)
    except RuntimeError as e:
        print("live_support: %s" % e, file=sys.stderr)
        return 1
    report(out, args.compare)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
