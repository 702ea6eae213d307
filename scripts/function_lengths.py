#!/usr/bin/env python3
"""Lists the functions of C++ sources longer than a limit (default 80 lines), longest first.

Usage: function_lengths.py [--max N] [--allow [FILE:]NAME]... FILE_OR_DIR...
Exit 1 if any function is longer, unless an --allow names it: NAME as printed (e.g. main,
Class::method), FILE a path suffix of its file (e.g. src/tools/bed_study.cpp). Allowed long
functions are still listed; an --allow that matches no long function is reported (stale).
A function is a top-level (or namespace-level) brace block whose opening line holds a ')'
before the '{'; lambdas and blocks inside it count toward it. Good enough for this code base's
style (clang-format, one function a block), not a C++ parser.
"""
import argparse
import os
import re
import sys

from source_tree import source_files


def strip(line, in_comment):
    out, i = "", 0
    while i < len(line):
        if in_comment:
            j = line.find("*/", i)
            if j < 0:
                return out, True
            i, in_comment = j + 2, False
        elif line.startswith("/*", i):
            in_comment, i = True, i + 2
        elif line.startswith("//", i):
            break
        elif line[i] in "\"'":
            q, j = line[i], i + 1
            while j < len(line) and line[j] != q:
                j += 2 if line[j] == "\\" else 1
            out, i = out + q + q, j + 1
        else:
            out, i = out + line[i], i + 1
    return out, in_comment


def functions(path):
    with open(path, errors="replace") as f:
        lines = f.readlines()
    depth, in_comment, start, name, ns_depths = 0, False, None, None, []
    header = ""
    for no, raw in enumerate(lines, 1):
        code, in_comment = strip(raw, in_comment)
        for ch in code:
            if ch == "{":
                if start is None and depth == len(ns_depths):
                    if re.search(r"\b(namespace|struct|class|enum|union)\b[^;()]*$", header):
                        ns_depths.append(depth)
                    elif ")" in header:
                        m = re.findall(r"([A-Za-z_][A-Za-z0-9_:~]*)\s*\(", header)
                        start, name = no, (m[0] if m else "?")
                depth += 1
                header = ""
            elif ch == "}":
                depth -= 1
                if start is not None and depth == len(ns_depths):
                    yield name, start, no
                    start = None
                elif ns_depths and depth == ns_depths[-1]:
                    ns_depths.pop()
                header = ""
            elif ch == ";" and start is None:
                header = ""
            else:
                header += ch
        header += " "


def allows(rule, path, name):
    """True when an --allow rule ([FILE:]NAME) names the function `name` of file `path`."""
    m = re.match(r"^([^:]+):([^:].*)$", rule)  # FILE:NAME; a NAME's '::' is not the separator
    where, what = (m.group(1), m.group(2)) if m else ("", rule)
    if what != name:
        return False
    norm = os.path.normpath(path).replace(os.sep, "/")
    where = os.path.normpath(where).replace(os.sep, "/") if where else ""
    return not where or norm == where or norm.endswith("/" + where)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--max", type=int, default=80)
    ap.add_argument("--allow", action="append", default=[], metavar="[FILE:]NAME",
                    help="a long function not to fail on (an exception still being worked on)")
    ap.add_argument("paths", nargs="+")
    a = ap.parse_args()
    files = source_files(a.paths, (".cpp", ".h"))
    long = []
    for f in sorted(files):
        for name, s, e in functions(f):
            if e - s + 1 > a.max:
                long.append((e - s + 1, f, s, name))
    failing, used = [], set()
    for n, f, s, name in sorted(long, reverse=True):
        rules = [r for r in a.allow if allows(r, f, name)]
        used.update(rules)
        print("%4d lines  %s:%d  %s%s" % (n, f, s, name, "  (allowed)" if rules else ""))
        if not rules:
            failing.append(name)
    for rule in a.allow:
        if rule not in used:
            print("note: --allow %s matches no function longer than %d lines: remove it" % (rule, a.max))
    print("%d function(s) longer than %d lines" % (len(failing), a.max) +
          (", %d more allowed" % (len(long) - len(failing)) if len(long) > len(failing) else ""))
    return 1 if failing else 0


if __name__ == "__main__":
    sys.exit(main())
