#!/usr/bin/env python3
"""Checks every relative link in README.md and doc/*.md (and doc/**/*.md) of the package: the
file (or folder) it names must exist, and a '#anchor' must be a heading of the linked Markdown
file. External links (http, https, mailto) are not fetched.

Usage: check_doc_links.py [--root DIR] [--junit FILE]
Prints one line per broken link, then "N links checked, N broken"; exit 1 if any is broken.
With --junit, writes one JUnit test case per Markdown file.
"""
import argparse
import os
import re
import sys
from xml.sax.saxutils import quoteattr

LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^\s*\[[^\]]+\]:\s*(\S+)", re.M)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE = re.compile(r"`[^`\n]*`")


def anchors(md_path):
    """GitHub-style anchors of the headings of a Markdown file."""
    out = set()
    with open(md_path, encoding="utf-8", errors="replace") as f:
        text = FENCE.sub("", f.read())
    for line in text.splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            a = m.group(1).strip().lower()
            a = re.sub(r"[^\w\- ]", "", a)
            out.add(a.replace(" ", "-"))
    return out


def links(md_path):
    with open(md_path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    text = FENCE.sub("", text)
    text = CODE.sub("", text)
    return LINK.findall(text) + REF_DEF.findall(text)


def check_file(md_path):
    broken = []
    base = os.path.dirname(md_path)
    for target in links(md_path):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        full = os.path.normpath(os.path.join(base, path)) if path else md_path
        if not os.path.exists(full):
            broken.append("%s: link to %s: no such file" % (md_path, target))
        elif anchor and full.endswith(".md") and anchor.lower() not in anchors(full):
            broken.append("%s: link to %s: no heading '#%s' in %s" % (md_path, target, anchor, full))
    return broken, len(links(md_path))


def markdown_files(root):
    files = [os.path.join(root, "README.md")]
    for d, _, fs in os.walk(os.path.join(root, "doc")):
        files += [os.path.join(d, f) for f in sorted(fs) if f.endswith(".md")]
    return [f for f in files if os.path.exists(f)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    ap.add_argument("--junit")
    a = ap.parse_args()
    root = os.path.normpath(a.root)
    cases, total, all_broken = [], 0, []
    for md in markdown_files(root):
        broken, n = check_file(md)
        total += n
        all_broken += broken
        cases.append((os.path.relpath(md, root), broken))
    for line in all_broken:
        print(line)
    print("%d links checked, %d broken" % (total, len(all_broken)))
    if a.junit:
        os.makedirs(os.path.dirname(os.path.abspath(a.junit)), exist_ok=True)
        with open(a.junit, "w") as f:
            f.write('<?xml version="1.0" encoding="utf-8"?>\n')
            f.write('<testsuite name="doc_links" tests="%d" failures="%d">\n'
                    % (len(cases), sum(1 for _, b in cases if b)))
            for name, broken in cases:
                f.write('  <testcase classname="doc_links" name=%s>' % quoteattr(name))
                if broken:
                    f.write('<failure message=%s/>' % quoteattr("; ".join(broken)))
                f.write("</testcase>\n")
            f.write("</testsuite>\n")
    return 1 if all_broken else 0


if __name__ == "__main__":
    sys.exit(main())
