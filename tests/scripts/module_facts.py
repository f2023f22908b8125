#!/usr/bin/env python3
"""Module-size facts for the house rules: long files, long functions, module cycles.

Run from the repository root: ``python3 tests/scripts/module_facts.py``. Standard library only.

Prints
  (a) every ``.rs`` file over 600 lines, production and test separately (test: a file named
      ``tests.rs``, a file under a ``tests/`` or ``benches/`` directory, or a module declared
      under ``#[cfg(test)]``);
  (b) every production function over 150 lines, from its ``fn`` line to its closing brace;
  (c) module import cycles inside each crate: the nodes are the module files under a crate's
      ``src/``, an edge A -> B when A's code names B through a ``crate::``, ``super::`` or
      ``self::`` path (``use`` lists expanded), and a cycle is a strongly connected component of
      two or more modules.

The scan is approximate: it is a small lexer and brace matcher, not a Rust parser. Comments
(doc links included), strings and character literals are blanked first; ``#[cfg(test)]`` inline
modules are left out of (b) and (c); a path resolves to the deepest module file it reaches;
``#[path]`` attributes, macros and paths inside non-test inline modules are not understood.
"""

import re
import sys
from pathlib import Path

FILE_LINES, FN_LINES = 600, 150
SKIP_DIRS = {"target", ".git", "python", "fuzz", "boards"}
RAW_STR = re.compile(r'b?r(#*)"')
CFG_TEST = re.compile(r"#\[cfg\((?:[^\]]*\btest\b[^\]]*)\)\]")


def blank(src):
    """Source with comments, strings and char literals replaced by spaces (newlines kept)."""
    out, i, n = [], 0, len(src)
    keep_lines = lambda s: re.sub(r"[^\n]", " ", s)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                depth += src.startswith("/*", j) - src.startswith("*/", j)
                j += 2 if src[j : j + 2] in ("/*", "*/") else 1
        elif (m := RAW_STR.match(src, i)) and not (i and (src[i - 1].isalnum() or src[i - 1] == "_")):
            j = src.find('"' + m.group(1), m.end())
            j = n if j < 0 else j + 1 + len(m.group(1))
        elif c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            j += 1
        elif m := re.compile(r"'(\\.[^']*|[^\\'])'").match(src, i):
            j = m.end()
        else:
            out.append(c)
            i += 1
            continue
        out.append(keep_lines(src[i:j]))
        i = j
    return "".join(out)


def close_brace(text, i):
    """Index just past the brace that closes the ``{`` at ``text[i]``."""
    depth = 0
    for j in range(i, len(text)):
        depth += {"{": 1, "}": -1}.get(text[j], 0)
        if depth == 0:
            return j + 1
    return len(text)


def test_spans(text):
    """(start, end) spans of ``#[cfg(test)] mod x { ... }`` blocks, and names of ``#[cfg(test)] mod x;``."""
    spans, test_children = [], set()
    for m in CFG_TEST.finditer(text):
        if "not(test)" in m.group(0):
            continue
        d = re.compile(r"(?:\s*#\[[^\]]*\])*\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+)\s*([;{])").match(text, m.end())
        if not d:
            continue
        if d.group(2) == ";":
            test_children.add(d.group(1))
        else:
            spans.append((m.start(), close_brace(text, d.end() - 1)))
    return spans, test_children


def without(text, spans):
    for a, b in spans:
        text = text[:a] + re.sub(r"[^\n]", " ", text[a:b]) + text[b:]
    return text


def signature_end(text, i):
    """Index of the ``{`` opening a function's body or of the ``;`` ending a declaration,
    from ``i`` inside its signature: a ``;`` within brackets (``[bool; 3]``) is part of a
    type, not the end."""
    depth = 0
    while i < len(text):
        c = text[i]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
        elif depth == 0 and c in "{;":
            return i
        i += 1
    return i


def long_functions(text):
    """(name, first line, length in lines) of every ``fn`` body over FN_LINES lines."""
    for m in re.finditer(r"\bfn\s+(\w+)", text):
        body = signature_end(text, m.end())
        if body < len(text) and text[body] == "{":
            first = text.count("\n", 0, m.start()) + 1
            lines = text.count("\n", m.start(), close_brace(text, body)) + 1
            if lines > FN_LINES:
                yield m.group(1), first, lines


def use_paths(text):
    """Every ``crate::``/``super::``/``self::`` path in ``text`` as a list of segments."""
    paths = []
    for m in re.finditer(r"(?<![\w:])(crate|super|self)\s*::", text):
        if re.search(r"\bin\s*$", text[max(0, m.start() - 4) : m.start()]):
            continue  # pub(in crate::x) is a visibility, not a use
        paths += expand(text, m.start(), [])[0]
    return paths


def expand(text, i, prefix):
    """Expand the path or use tree starting at ``text[i]``; returns (paths, end index)."""
    segs = list(prefix)
    while True:
        m = re.compile(r"\s*(\w+|\*|\{)").match(text, i)
        if not m:
            return [segs], i
        i, tok = m.end(), m.group(1)
        if tok == "{":  # a use list: each item extends the prefix read so far
            paths = []
            while not (end := re.compile(r"\s*\}").match(text, i)):
                sub, i = expand(text, i, segs)
                paths += sub
                sep = re.compile(r"\s*(?:as\s+\w+\s*)?(,?)").match(text, i)
                i = sep.end()
                if not sep.group(1) and not re.compile(r"\s*\}").match(text, i):
                    return paths, i  # not a use list after all
            return paths, end.end()
        if tok not in ("self", "*") or not segs:
            segs.append(tok)
        nxt = re.compile(r"\s*::").match(text, i)
        if not nxt:
            return [segs], i
        i = nxt.end()


def resolve(path, here, modules):
    """The deepest module in ``modules`` that ``path`` (seen from module ``here``) reaches."""
    head, rest = path[0], path[1:]
    base = () if head == "crate" else here[:-1] if head == "super" else here
    while rest and rest[0] == "super":
        base, rest = base[:-1], rest[1:]
    best = base if base in modules else None
    for seg in rest:
        base = base + (seg,)
        if base in modules:
            best = base
    return best


def module_of(rel):
    """Module path of a file relative to ``src/``: ``a/b.rs`` and ``a/b/mod.rs`` are ``(a, b)``."""
    parts = list(rel.with_suffix("").parts)
    if parts[-1] in ("mod", "lib", "main"):
        parts.pop()
    return tuple(parts)


def sccs(graph):
    """Strongly connected components of two or more nodes (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v), on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while not comp or comp[-1] != v:
                comp.append(stack.pop())
                on.discard(comp[-1])
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def main():
    root = Path(".")
    files = sorted(p for p in root.rglob("*.rs") if not SKIP_DIRS & set(p.parts))
    texts = {p: blank(p.read_text()) for p in files}
    test_files = {p for p in files if p.name == "tests.rs" or {"tests", "benches"} & set(p.parts)}
    for p, text in texts.items():  # files declared as #[cfg(test)] mod x;
        for name in test_spans(text)[1]:
            folder = p.parent if p.name in ("lib.rs", "main.rs", "mod.rs") else p.with_suffix("")
            test_files |= {folder / f"{name}.rs", folder / name / "mod.rs"}
    while True:  # children of test-only modules are test-only too
        more = {p for p in files if p not in test_files and any(t.with_suffix("") in p.parents for t in test_files)}
        if not more:
            break
        test_files |= more

    print(f"(a) files over {FILE_LINES} lines")
    for label, test in (("production", False), ("test", True)):
        big = [(len(p.read_text().splitlines()), p) for p in files if (p in test_files) == test]
        big = sorted((n, p) for n, p in big if n > FILE_LINES)
        print(f"  {label}: {len(big)}")
        for n, p in reversed(big):
            print(f"    {n:5}  {p}")

    prod = {p: without(t, test_spans(t)[0]) for p, t in texts.items() if p not in test_files}
    long = sorted(((n, f"{p}:{line}", name) for p, t in prod.items() for name, line, n in long_functions(t)), reverse=True)
    print(f"(b) production functions over {FN_LINES} lines: {len(long)}")
    for n, where, name in long:
        print(f"    {n:5}  {name}  {where}")

    crates = sorted({p.parent for p in root.rglob("Cargo.toml") if not SKIP_DIRS & set(p.parts)})
    cycles = []
    for crate in crates:
        src = crate / "src"
        mods = {module_of(p.relative_to(src)): p for p in prod if src in p.parents}
        graph = {m: set() for m in mods}
        for m, p in mods.items():
            for path in use_paths(prod[p]):
                target = resolve(path, m, mods)
                if target is not None and target != m:
                    graph[m].add(target)
        cycles += [(crate, c) for c in sccs(graph)]
    print(f"(c) module cycles inside crates: {len(cycles)}")
    for crate, comp in cycles:
        print(f"    {crate}: {{{', '.join('::'.join(m) or 'crate' for m in comp)}}}")


if __name__ == "__main__":
    main()
