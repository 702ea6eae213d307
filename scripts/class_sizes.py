#!/usr/bin/env python3
"""Counts the methods and data members of every class and struct in C++ headers.

Usage: class_sizes.py [--max-methods N] [--max-data N] [--allow NAME]... [--all] FILE_OR_DIR...

A class with more than --max-methods (default 25) member functions, public and private, or
more than --max-data (default 15) data members is an offender unless a comment line
    // size: <reason>
stands in the comment block right above it (above its `template <...>` line, if any). Exit 1
when there is an offender without a reason that --allow (its qualified name, e.g. Outer::Inner)
does not name.

What counts:
  - methods: every member function declared or defined in the class, constructors, destructor
    and operators included; `= delete`d ones are not (they add no behaviour);
  - data members: non-static data members, each declarator of `int a, b;` once; static
    constants, types, aliases and enumerators are not members of the instance;
  - a nested class or struct is counted on its own (as Outer::Inner), not as part of its outer one.
Exempt by rule: parameter structs, a plain aggregate of knobs whose name ends in Params, Options
or Config and whose only method (if any) is validate(); their size is the number of knobs.

A rough parser (comments, strings, braces, angle brackets), good enough for this code base's
headers, not a C++ parser: a function-pointer data member would count as a method.
"""
import argparse
import re
import sys

from source_tree import source_files

KEYWORD_SKIP = {"using", "typedef", "friend", "static_assert", "enum"}
EXEMPT_NAME = re.compile(r"(Params|Options|Config)$")
SIZE_REASON = re.compile(r"^\s*//+\s*size:\s*\S", re.IGNORECASE)
TOKEN = re.compile(r"::|->|[A-Za-z_][A-Za-z0-9_]*|[0-9][0-9A-Za-z_.']*|\S")


def tokens_of(text):
    """(token, line) pairs of the code, comments, strings and preprocessor lines removed."""
    out, line, i, n = [], 1, 0, len(text)
    at_line_start = True
    while i < n:
        c = text[i]
        if c == "\n":
            line, at_line_start, i = line + 1, True, i + 1
            continue
        if c in " \t\r":
            i += 1
            continue
        if at_line_start and c == "#":  # preprocessor line (with continuations)
            while i < n and text[i] != "\n":
                i += 2 if text[i] == "\\" and i + 1 < n else 1
                if text[i - 1] == "\n":
                    line += 1
            continue
        at_line_start = False
        if text.startswith("//", i):
            while i < n and text[i] != "\n":
                i += 1
            continue
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            line += text.count("\n", i, j)
            i = j
            continue
        if c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(('""', line))
            i = j + 1
            continue
        m = TOKEN.match(text, i)
        out.append((m.group(0), line))
        i = m.end()
    return out


def is_ident(tok):
    return re.match(r"[A-Za-z_]", tok) is not None


class ClassInfo:
    def __init__(self, name, path, line):
        self.name, self.path, self.line = name, path, line
        self.methods = []  # names
        self.data = 0


def function_like(stmt):
    """True when the statement declares a function: `name (` outside template brackets, before any `=`."""
    angle = 0
    prev = None
    for tok in stmt:
        if tok == "=" and angle == 0:
            return False
        if tok == "operator":
            return True
        if tok == "<" and prev is not None and is_ident(prev):
            angle += 1
        elif tok == ">" and angle > 0:
            angle -= 1
        elif tok == "(" and angle == 0 and prev is not None and is_ident(prev):
            return prev not in ("alignas", "decltype")
        prev = tok
    return False


def method_name(stmt):
    for i, tok in enumerate(stmt):
        if tok == "operator":
            return "operator" + "".join(stmt[i + 1:i + 2])
        if tok == "(" and i > 0:
            return ("~" + stmt[i - 1]) if i > 1 and stmt[i - 2] == "~" else stmt[i - 1]
    return "?"


def declarators(stmt):
    """Number of comma-separated declarators of a data member declaration."""
    count, depth, angle, after_eq, prev = 1, 0, 0, False, None
    for tok in stmt:
        if tok in "([":
            depth += 1
        elif tok in ")]":
            depth -= 1
        elif tok == "=" and depth == 0 and angle == 0:
            after_eq = True
        elif tok == "<" and not after_eq and prev is not None and is_ident(prev):
            angle += 1
        elif tok == ">" and not after_eq and angle > 0:
            angle -= 1
        elif tok == "," and depth == 0 and angle == 0:
            count, after_eq = count + 1, False
        prev = tok
    return count


def strip_template_head(stmt):
    if stmt[:2] != ["template", "<"]:
        return stmt
    depth = 0
    for i, tok in enumerate(stmt[1:], 1):
        depth += 1 if tok == "<" else -1 if tok == ">" else 0
        if depth == 0:
            return stmt[i + 1:]
    return []


def classify(stmt, info):
    stmt = strip_template_head(stmt)
    if not stmt or stmt[0] in KEYWORD_SKIP or stmt[0] == "__classdef__":
        return
    if function_like(stmt):
        if stmt[-2:] != ["=", "delete"]:
            info.methods.append(method_name(stmt))
    elif stmt[0] != "static" and "static" not in stmt[:3]:
        info.data += declarators(stmt)


def class_head(stmt):
    """Index of the class keyword of the class a statement ending before '{' opens, or None."""
    for i, tok in enumerate(stmt):
        if tok in ("class", "struct", "union"):
            if i > 0 and stmt[i - 1] in ("enum", "friend"):
                return None
            rest = stmt[i + 1:]
            if not rest or not is_ident(rest[0]) or "(" in rest or "=" in rest:
                return None
            return i
    return None


def skip_balanced(toks, i):
    """Index after the brace block that opens at toks[i]."""
    depth = 0
    while i < len(toks):
        depth += 1 if toks[i][0] == "{" else -1 if toks[i][0] == "}" else 0
        i += 1
        if depth == 0:
            return i
    return i


def parse_scope(toks, i, path, outer, classes):
    """Parses declarations from toks[i] to the closing brace; returns the index after it.
    `outer` is the ClassInfo of the enclosing class, or None at namespace scope."""
    stmt, stmt_lines, ctor_init = [], [], False
    while i < len(toks):
        tok, line = toks[i]
        if tok == "}":
            if outer is not None and stmt:
                classify(stmt, outer)
            return i + 1
        if tok == ";":
            if outer is not None and stmt:
                classify(stmt, outer)
            stmt, stmt_lines, ctor_init, i = [], [], False, i + 1
            continue
        if outer is not None and not stmt and tok in ("public", "private", "protected") and \
                i + 1 < len(toks) and toks[i + 1][0] == ":":
            i += 2
            continue
        if tok == "{":
            k = class_head(stmt) if "namespace" not in stmt and "enum" not in stmt else None
            if "namespace" in stmt:
                i, stmt, stmt_lines = parse_scope(toks, i + 1, path, None, classes), [], []
            elif k is not None:
                qualified = (outer.name + "::" + stmt[k + 1]) if outer is not None else stmt[k + 1]
                info = ClassInfo(qualified, path, stmt_lines[k])
                classes.append(info)
                i = parse_scope(toks, i + 1, path, info, classes)
                stmt, stmt_lines = ["__classdef__"], [line]
            elif function_like(stmt) and not (ctor_init and (is_ident(stmt[-1]) or stmt[-1] == ">")):
                if outer is not None:
                    classify(stmt, outer)
                i, stmt, stmt_lines, ctor_init = skip_balanced(toks, i), [], [], False
            else:  # an initializer, an enum's or a lambda's body: part of the statement
                i = skip_balanced(toks, i)
                stmt.append("{}")
                stmt_lines.append(line)
            continue
        if tok == ":" and function_like(stmt) and stmt.count("(") == stmt.count(")"):
            ctor_init = True
        stmt.append(tok)
        stmt_lines.append(line)
        i += 1
    return i


def has_reason(lines, class_line):
    """True when a '// size: <reason>' line is in the comment block right above the class."""
    k = class_line - 2  # the line above, 0-based
    while k >= 0 and re.match(r"^\s*template\s*<", lines[k]):
        k -= 1
    while k >= 0 and re.match(r"^\s*(//|/\*|\*)", lines[k]):
        if SIZE_REASON.match(lines[k]):
            return True
        k -= 1
    return False


def classes_of(path):
    with open(path, errors="replace") as f:
        text = f.read()
    classes = []
    parse_scope(tokens_of(text), 0, path, None, classes)
    lines = text.split("\n")
    for c in classes:
        c.reason = has_reason(lines, c.line)
        c.exempt = bool(EXEMPT_NAME.search(c.name.split("::")[-1])) and \
            all(m == "validate" for m in c.methods)
    return classes


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-methods", type=int, default=25)
    ap.add_argument("--max-data", type=int, default=15)
    ap.add_argument("--allow", action="append", default=[],
                    help="qualified class name not to fail on (an exception still being worked on)")
    ap.add_argument("--all", action="store_true", help="list every class, not only the large ones")
    ap.add_argument("paths", nargs="+")
    a = ap.parse_args()
    files = source_files(a.paths, (".h", ".hpp"))
    offenders, allowed_used = [], set()
    print("methods  data  class  (file:line)  status")
    for f in sorted(files):
        for c in classes_of(f):
            large = len(c.methods) > a.max_methods or c.data > a.max_data
            if c.exempt:
                status = "exempt (parameter struct)"
            elif not large:
                status = "ok"
            elif c.reason:
                status = "ok (size: reason given)"
            elif c.name in a.allow:
                status = "ALLOWED (over the limits, on the allow-list)"
                allowed_used.add(c.name)
            else:
                status = "OVER the limits, no '// size:' reason"
                offenders.append(c)
            if a.all or large:
                print("%7d %5d  %s  (%s:%d)  %s" % (len(c.methods), c.data, c.name, f, c.line, status))
    for name in sorted(set(a.allow) - allowed_used):
        print("note: %s is allowed but not over the limits (or not found): remove it from the allow-list" % name)
    print("%d class(es) over %d methods or %d data members without a reason" %
          (len(offenders), a.max_methods, a.max_data))
    return 1 if offenders else 0


if __name__ == "__main__":
    sys.exit(main())
