#!/usr/bin/env bash
# Runs every test of nursing_bed (gtest executables, rostest files and the gap blind check:
# catkin's per-test targets, in lanes by scripts/run_test_lanes.py), then counts the
# individual test cases of all JUnit result files.
# Last line: "N passed, N failed". Exit 0 only if nothing failed and at least one test passed.
# A test executable that crashes or writes no result counts as failed (catkin's run_tests.py
# then writes MISSING-<name>.xml with one failed case). Set NB_SKIP_BUILD=1 to skip the build.
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$ROOT/build"
RESULTS="$BUILD/test_results"
LOG="$BUILD/test_output.log"
export PATH="/usr/bin:$PATH"
# Every test talks over loopback: the nodes and each rostest's own master advertise localhost,
# so a machine whose host name does not resolve (a fresh container, a chroot) runs them too.
export ROS_HOSTNAME="${ROS_HOSTNAME:-localhost}"

make_failed=0
if [[ "${NB_SKIP_BUILD:-0}" != 1 ]]; then
  mkdir -p "$BUILD"
  if ! bash "$ROOT/scripts/build.sh" >"$BUILD/build.log" 2>&1; then
    tail -n 60 "$BUILD/build.log"
    echo "run_tests: build failed (full log: $BUILD/build.log)"
    make_failed=1
  fi
fi

# Old results must never count.
rm -rf "$RESULTS"
mkdir -p "$RESULTS"

if [[ $make_failed -eq 0 ]]; then
  echo "run_tests: every test target, in lanes (scripts/run_test_lanes.py; output: $LOG)"
  : >"$LOG"
  # A failing test is counted from its result file below; exit 1 (a target exited non-zero) alone
  # is not a failure, any other exit means the lanes themselves broke.
  /usr/bin/python3 "$ROOT/scripts/run_test_lanes.py" --build "$BUILD" --source "$ROOT" --log "$LOG"
  rc=$?
  if [[ $rc -eq 1 ]]; then
    echo "run_tests: some test targets exited non-zero (full output: $LOG)"
  elif [[ $rc -ne 0 ]]; then
    echo "run_tests: scripts/run_test_lanes.py failed (exit $rc)"
    make_failed=1
  fi
fi

/usr/bin/python3 - "$RESULTS" "$make_failed" "$LOG" <<'PY'
import os
import sys
import xml.etree.ElementTree as ET

results_dir, make_failed, log = sys.argv[1], sys.argv[2] == "1", sys.argv[3]

rows = []          # (file, passed, failed, skipped)
failed_names = []  # (name, message)

# For a test executable that left no result (MISSING-*.xml): the gtest case it was running.
crashed_in = {}
try:
    running = None
    with open(log, errors="replace") as f:
        for line in f:
            line = line.rstrip("\n")
            if line.startswith("-- run_tests.py: execute commands"):
                running = None
            elif line.startswith("[ RUN      ] "):
                running = line[13:].strip()
            elif line.startswith(("[       OK ] ", "[  FAILED  ] ", "[  SKIPPED ] ")):
                running = None
            elif line.startswith("Cannot find results, writing failure results to '"):
                missing = os.path.basename(line.split("'")[1])
                if running:
                    crashed_in[missing] = running
except OSError:
    pass

def short(text, n=300):
    text = " ".join((text or "").split())
    return text if len(text) <= n else text[:n] + " ..."

def suites(root):
    if root.tag == "testsuite":
        return [root]
    return [s for s in root.iter("testsuite")]

def count_file(path, rel):
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError) as e:
        failed_names.append((rel, "unreadable result file: %s" % e))
        return 0, 1, 0
    if root.tag not in ("testsuite", "testsuites"):
        failed_names.append((rel, "not a JUnit result file (root <%s>)" % root.tag))
        return 0, 1, 0
    passed = failed = skipped = 0
    for case in root.iter("testcase"):
        name = case.get("name", "?")
        cls = case.get("classname", "")
        full = "%s.%s" % (cls, name) if cls else name
        bad = case.find("failure")
        if bad is None:
            bad = case.find("error")
        if bad is None and cls == "rostest.runner.RosTest":
            # rostest's own case "test<name>" only says that the test node ran and wrote its
            # result file (rosunit-<name>.xml), whose cases are counted: count it only if it failed
            # (node missing, crashed, timed out, no results).
            continue
        if bad is not None:
            failed += 1
            # gtest: "file:line\nexpected ..." in the message; Python: first line of the text.
            msg = bad.get("message") or next(
                (l for l in (bad.text or "").splitlines() if l.strip()), "")
            if rel.startswith("MISSING-"):
                msg = "no result file: the test crashed, timed out or did not run. " + msg
                if rel in crashed_in:
                    msg = "crashed in gtest case %s; %s" % (crashed_in[rel], msg)
            failed_names.append(("%s [%s]" % (full, rel), short(msg)))
        elif (case.find("skipped") is not None or case.get("status") == "notrun"
              or case.get("result") == "skipped"):
            skipped += 1
        else:
            passed += 1
    # Failures or errors reported by a suite but not attached to any test case
    # (e.g. a failing SetUpTestSuite, a rostest that could not start its nodes).
    attr_bad = 0
    for s in suites(root):
        try:
            attr_bad += int(s.get("failures", 0)) + int(s.get("errors", 0))
        except ValueError:
            pass
    if root.tag == "testsuites" and not list(root.iter("testsuite")):
        attr_bad = int(root.get("failures", 0) or 0) + int(root.get("errors", 0) or 0)
    if attr_bad > failed:
        failed_names.append((rel, "%d failure(s)/error(s) outside any test case"
                             % (attr_bad - failed)))
        failed = attr_bad
    return passed, failed, skipped

for dirpath, dirnames, filenames in sorted(os.walk(results_dir)):
    dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
    for fn in sorted(filenames):
        if not fn.endswith(".xml"):
            continue
        path = os.path.join(dirpath, fn)
        rel = os.path.relpath(path, results_dir)
        p, f, s = count_file(path, os.path.basename(rel))
        rows.append((rel, p, f, s))

if make_failed:
    failed_names.append(("build/make run_tests", "the build or the test run itself failed"))

width = max([len(r[0]) for r in rows] + [len("result file")])
print()
print("%-*s %7s %7s %7s" % (width, "result file", "passed", "failed", "skipped"))
print("-" * (width + 24))
for rel, p, f, s in rows:
    print("%-*s %7d %7d %7d" % (width, rel, p, f, s))
if not rows:
    print("(no result files in %s)" % results_dir)

total_passed = sum(r[1] for r in rows)
total_failed = sum(r[2] for r in rows) + (1 if make_failed else 0)
total_skipped = sum(r[3] for r in rows)

if failed_names:
    print()
    print("FAILED:")
    for name, msg in failed_names:
        print("  %s" % name)
        if msg:
            print("      %s" % msg)
    print("(full test output: %s)" % log)
if total_skipped:
    print("%d skipped" % total_skipped)
print()
print("%d passed, %d failed" % (total_passed, total_failed))
sys.exit(0 if total_failed == 0 and total_passed > 0 else 1)
PY
