#!/usr/bin/env python3
"""Runs catkin's test targets of nursing_bed in lanes, so the test command's wall time is the
longest lane rather than the sum of all tests.

  background lane (nice 19): the gtest executables, then the gap blind check; CPU-bound, and at
      nice 19 they take only the CPU the rostests leave (but the real-time gtests, REAL_TIME_GTESTS,
      run in the rostest lanes).
  rostest lanes: the light rostests (beds of fewer than --heavy-cells cells) --lanes at a time;
      those that launch the rig emulator (real_bed.launch) one at a time among themselves;
      then the heavy rostests alone, since their timing claims need the CPU.

Each rostest starts its own master on a free port, so rostests can run side by side. Every
target's output goes to LOGDIR/<target>.log; at the end all of them are appended, in target
order, to --log (the result counter reads crash traces from it).

usage: run_test_lanes.py --build DIR --source DIR --log FILE [--lanes N] [--heavy-cells N] [--only REGEX]
"""
import argparse
import glob
import os
import re
import subprocess
import sys
import threading
import time

PREFIX = "_run_tests_nursing_bed_"
# Gtests that time exchanges over loopback sockets against the wall clock (the Modbus driver
# and the rig emulator's server): at nice 19 beside the rostests their threads starve for tens
# of ms, so they run in the rostest lanes, one at a time with the emulator's rostests.
REAL_TIME_GTESTS = {"gtest_test_rig"}


def test_targets(build):
    """The per-test targets catkin generated (not the aggregates), in make's order."""
    out = subprocess.run(["make", "-C", build, "help"], capture_output=True, text=True, check=True).stdout
    names = [line.split()[-1] for line in out.splitlines() if line.startswith("... " + PREFIX)]
    return [n for n in names if re.match(PREFIX + r"(gtest|rostest|blind)_.+", n)]


def command_of(build, target):
    """The shell command catkin generated for a per-test target. The targets are not run through
    make: each of them depends on clean_test_results, which would delete the results of the
    tests running beside it."""
    rules = os.path.join(build, "CMakeFiles", target + ".dir", "build.make")
    lines = open(rules).read().splitlines()
    head = "CMakeFiles/%s:" % target
    for i, line in enumerate(lines):
        if line.startswith(head):
            commands = []
            for rule_line in lines[i + 1:]:
                if not rule_line.startswith("\t"):
                    break
                commands.append(rule_line[1:])
            if commands:
                return " && ".join(commands)
    raise RuntimeError("no command for %s in %s" % (target, rules))


def rostest_file(source, target):
    """The .test file behind a rostest target (its name is the file's path with '/' as '_')."""
    suffix = target[len(PREFIX + "rostest_"):]
    for path in glob.glob(os.path.join(source, "test", "**", "*.test"), recursive=True):
        if os.path.relpath(path, source).replace("/", "_") == suffix:
            return path
    return None


def time_limit_of(test_file):
    """The largest time-limit of a .test file's tests [s] (rostest's default 60 s if none is given)."""
    limits = [float(v) for v in re.findall(r'time-limit="([0-9.]+)"', open(test_file).read())]
    return max(limits, default=60.0)


def cells_of(test_file):
    """rows x cols of the bed a .test file launches (its first rows/cols args), 0 if none."""
    text = open(test_file).read()
    dims = []
    for key in ("rows", "cols"):
        m = re.search(r'name="%s"\s+value="(\d+)"' % key, text)
        dims.append(int(m.group(1)) if m else 0)
    return dims[0] * dims[1]


class Runner:
    def __init__(self, build, logdir):
        self.build, self.logdir = build, logdir
        self.lock = threading.Lock()
        self.done = 0
        self.total = 0

    def run(self, target, nice=False):
        log = os.path.join(self.logdir, target + ".log")
        cmd = ["bash", "-c", command_of(self.build, target)]
        if nice:
            cmd = ["nice", "-n", "19"] + cmd
        start = time.time()
        with open(log, "w") as f:
            f.write("-- run_test_lanes: %s\n" % target)
            f.flush()
            rc = subprocess.run(cmd, cwd=self.build, stdout=f, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL).returncode
        with self.lock:
            self.done += 1
            print("run_tests: [%d/%d] %s %s (%.0f s)" % (self.done, self.total, target[len(PREFIX):],
                  outcome(log, rc), time.time() - start), flush=True)
        return rc


def outcome(log, rc):
    """The progress word for one target: catkin's test commands exit 0 even when a test fails,
    so the log's own verdicts (rostest's RESULT, gtest's FAILED lines) are read too."""
    if rc != 0:
        return "exit %d" % rc
    with open(log, errors="replace") as f:
        text = f.read()
    return "failed" if ("RESULT: FAIL" in text or "[  FAILED  ]" in text) else "ok"


def run_pool(runner, targets, lanes, exclusive):
    """Runs targets `lanes` at a time; those in `exclusive` never run beside each other."""
    pending = list(targets)
    cond = threading.Condition()
    state = {"exclusive_busy": False}
    rcs = []

    def take():
        with cond:
            while True:
                if not pending:
                    return None
                for i, t in enumerate(pending):
                    if t not in exclusive or not state["exclusive_busy"]:
                        if t in exclusive:
                            state["exclusive_busy"] = True
                        return pending.pop(i)
                cond.wait()

    def lane():
        while True:
            t = take()
            if t is None:
                return
            rcs.append(runner.run(t))
            if t in exclusive:
                with cond:
                    state["exclusive_busy"] = False
                    cond.notify_all()

    threads = [threading.Thread(target=lane) for _ in range(max(1, lanes))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return rcs


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build", required=True, help="the catkin build directory")
    ap.add_argument("--source", required=True, help="the package's source directory")
    ap.add_argument("--log", required=True, help="all targets' output, appended in target order")
    ap.add_argument("--lanes", type=int, default=2, help="light rostests side by side (default 2)")
    ap.add_argument("--heavy-cells", type=int, default=100,
                    help="a rostest of a bed of at least this many cells runs alone (default 100)")
    ap.add_argument("--only", help="run only the targets whose name matches this regular expression")
    args = ap.parse_args()
    if args.lanes < 1:
        ap.error("--lanes must be at least 1")

    targets = test_targets(args.build)
    if args.only:
        targets = [t for t in targets if re.search(args.only, t)]
    background, light, heavy, emulator = [], [], [], set()
    for t in targets:
        if t[len(PREFIX):] in REAL_TIME_GTESTS:
            light.append(t)
            emulator.add(t)
            continue
        if not t.startswith(PREFIX + "rostest_"):
            background.append(t)
            continue
        f = rostest_file(args.source, t)
        if f is not None and cells_of(f) >= args.heavy_cells:
            heavy.append(t)
        else:
            light.append(t)
            if f is not None and "real_bed.launch" in open(f).read():
                emulator.add(t)
    # Longest first (by time limit), so the lanes end together.
    files = {t: rostest_file(args.source, t) for t in light}
    light.sort(key=lambda t: -time_limit_of(files[t]) if files[t] else 0.0)
    # The blind check is the longest: start it after the quick gtests, never before them.
    background.sort(key=lambda t: t.startswith(PREFIX + "blind_"))

    logdir = os.path.join(args.build, "test_logs")
    os.makedirs(logdir, exist_ok=True)
    runner = Runner(args.build, logdir)
    runner.total = len(targets)
    print("run_tests: %d targets: %d in the background lane, %d light rostests and real-time gtests "
          "in %d lanes, %d heavy alone" % (len(targets), len(background), len(light), args.lanes, len(heavy)),
          flush=True)

    bg_rcs = []
    bg = threading.Thread(target=lambda: bg_rcs.extend(runner.run(t, nice=True) for t in background))
    bg.start()
    rcs = run_pool(runner, light, args.lanes, emulator)
    rcs += run_pool(runner, heavy, 1, set())
    bg.join()
    rcs += bg_rcs

    with open(args.log, "a") as out:
        for t in targets:
            path = os.path.join(logdir, t + ".log")
            if os.path.exists(path):
                out.write(open(path, errors="replace").read())
    return 0 if all(rc == 0 for rc in rcs) else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except Exception as e:  # exit 1 means "a test target failed"; this is the lanes' own failure
        print("run_test_lanes: %s" % e, file=sys.stderr)
        sys.exit(3)
