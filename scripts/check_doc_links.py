#!/usr/bin/env python3
"""Checks the package's documentation references.

- Markdown (README.md, CHANGELOG.md, doc/**/*.md): every relative link must name an existing file
  (or folder), and a '#anchor' must be a heading of the linked Markdown file. External links
  (http, https, mailto) are not fetched.
- Comments of the code and configuration (src/, include/, scripts/, test/, config/: C++ // and
  /* */ comments, Python comments and docstrings, '#' comments of shell, YAML and CMake, XML
  <!-- --> comments): every path under doc/ they mention (a page, or a page and '#anchor') must
  exist, with the anchor a heading of that page.
- Neither may mention a file outside the repository: the shared specifications beside it, an
  absolute path of the machine's work area, a specifications folder (the OUTSIDE pattern).

Usage: check_doc_links.py [--root DIR] [--junit FILE]
Prints one line per broken reference ("file:line: ..." for comments), then
"N links checked, N broken"; exit 1 if any is broken. With --junit, writes one JUnit test case
per Markdown file and one per code file with references.
"""
import argparse
import io
import os
import re
import sys
import tokenize
from xml.sax.saxutils import quoteattr

LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^\s*\[[^\]]+\]:\s*(\S+)", re.M)
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE = re.compile(r"`[^`\n]*`")
# A path under doc/ in a comment; not part of a longer path (nursing_bed/doc/..., /x/doc/...).
DOC_PATH = re.compile(r"(?<![\w./-])doc/[A-Za-z0-9_./-]*[A-Za-z0-9_](?:#[A-Za-z0-9_-]+)?")
# Files outside the repository: the shared specification folder, absolute work paths.
OUTSIDE = re.compile(r"\.\./shared|/work/|(?<![\w-])specs/")
# A bare Markdown file name in a comment ("see run_data.md"); it must name a page of the repository.
BARE_MD = re.compile(r"(?<![\w./-])[\w-]+\.md\b")
CODE_DIRS = ("src", "include", "scripts", "test", "config")
CPP_EXT = (".h", ".hpp", ".cpp", ".cc")
HASH_EXT = (".sh", ".yaml", ".yml", ".cmake", ".txt", ".rviz")
XML_EXT = (".launch", ".test", ".xml")


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


def outside_mentions(path, lines_with_text):
    """'path:line: mention of a file outside the repository' for each (line, text) that has one."""
    return ["%s:%d: mentions a file outside the repository (%s)" % (path, line, m.group(0))
            for line, text in lines_with_text for m in OUTSIDE.finditer(text)]


def check_file(md_path):
    with open(md_path, encoding="utf-8", errors="replace") as f:
        text = f.read()
    broken = outside_mentions(md_path, enumerate(text.splitlines(), 1))
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
    files = [os.path.join(root, "README.md"), os.path.join(root, "CHANGELOG.md")]
    for d, _, fs in os.walk(os.path.join(root, "doc")):
        files += [os.path.join(d, f) for f in sorted(fs) if f.endswith(".md")]
    return [f for f in files if os.path.exists(f)]


def cpp_comments(text):
    """(line, comment text) of every // and /* */ comment, string and char literals skipped."""
    out, i, line, n = [], 0, 1, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append((line, text[i + 2:j]))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j
            for k, part in enumerate(text[i + 2:j].split("\n")):
                out.append((line + k, part))
            line += text.count("\n", i, j)
            i = j + 2
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                i += 1
                continue
            end = text.find(")" + m.group(1) + '"', i)
            end = n if end < 0 else end + len(m.group(1)) + 2
            line += text.count("\n", i, end)
            i = end
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            i = j + 1
        else:
            i += 1
    return out


def python_comments(text):
    """(line, text) of every comment and docstring (a string standing as a statement)."""
    out, prev = [], tokenize.NEWLINE
    statement_start = (tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT)
    try:
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                out.append((tok.start[0], tok.string))
                continue
            if tok.type == tokenize.NL:
                continue
            if tok.type == tokenize.STRING and prev in statement_start:
                out += [(tok.start[0] + k, part) for k, part in enumerate(tok.string.split("\n"))]
            prev = tok.type
    except (tokenize.TokenError, IndentationError, SyntaxError):
        return hash_comments(text)
    return out


def hash_comments(text):
    """(line, text) after a '#' that starts a line or follows a blank (shell, YAML, CMake)."""
    out = []
    for no, line in enumerate(text.splitlines(), 1):
        m = re.search(r"(?:^|\s)#(.*)$", line)
        if m:
            out.append((no, m.group(1)))
    return out


def xml_comments(text):
    out = []
    for m in re.finditer(r"<!--(.*?)-->", text, re.S):
        first = text.count("\n", 0, m.start()) + 1
        for k, part in enumerate(m.group(1).split("\n")):
            out.append((first + k, part))
    return out


def comments_of(path, text):
    """The comments of a code or configuration file, or None for a kind of file not checked."""
    if path.endswith(CPP_EXT):
        return cpp_comments(text)
    if path.endswith(".py") or text.startswith("#!") and "python" in text.split("\n", 1)[0]:
        return python_comments(text)
    if path.endswith(HASH_EXT) or os.path.basename(path) == "CMakeLists.txt" or text.startswith("#!"):
        return hash_comments(text)
    if path.endswith(XML_EXT):
        return xml_comments(text)
    return None


def check_code_file(root, path):
    """Broken doc references and outside mentions in one file's comments, and how many were checked."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except (UnicodeDecodeError, OSError):
        return [], 0
    comments = comments_of(path, text)
    if comments is None:
        return [], 0
    rel = os.path.relpath(path, root)
    broken = outside_mentions(rel, comments)
    count = 0
    pages = markdown_names(root)
    for line, comment in comments:
        for m in BARE_MD.finditer(comment):
            count += 1
            if m.group(0) not in pages:
                broken.append("%s:%d: mention of %s: no such page in the repository" % (rel, line, m.group(0)))
        for m in DOC_PATH.finditer(comment):
            count += 1
            target = m.group(0)
            doc_path, _, anchor = target.partition("#")
            full = os.path.join(root, doc_path)
            if not os.path.exists(full):
                broken.append("%s:%d: mention of %s: no such file" % (rel, line, target))
            elif anchor and full.endswith(".md") and anchor.lower() not in anchors(full):
                broken.append("%s:%d: mention of %s: no heading '#%s' in %s" % (rel, line, target, anchor, doc_path))
    return broken, count


_MD_NAMES = {}


def markdown_names(root):
    """File names of every Markdown file of the repository (build trees and .git left out)."""
    if root not in _MD_NAMES:
        names = set()
        for d, dirs, fs in os.walk(root):
            dirs[:] = [x for x in dirs if not x.startswith(".") and x not in ("build", "devel")]
            names.update(f for f in fs if f.endswith(".md"))
        _MD_NAMES[root] = names
    return _MD_NAMES[root]


def code_files(root):
    files = []
    for top in CODE_DIRS:
        for d, dirs, fs in os.walk(os.path.join(root, top)):
            dirs.sort()
            files += [os.path.join(d, f) for f in sorted(fs)]
    return files


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
    for path in code_files(root):
        broken, n = check_code_file(root, path)
        total += n
        all_broken += broken
        if n or broken:
            cases.append((os.path.relpath(path, root), broken))
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
