#!/usr/bin/env python3
"""check_includes.py — the #include graph of server/, protocol/, common/, clients/c/ and the kernels'
layout headers (kernels/*_layout.h) has no cycles, and protocol/ stands alone.

A module is a source file's path without its extension (server/hub.c and server/hub.h are one
module, server/hub). Module A depends on module B when A's .c or .h includes B's header, found
as the compiler finds it: next to the including file, then in protocol/, common/, server/,
clients/c/, kernels/ (the Makefile's -I order). A cycle among modules means a newcomer must hold both files in mind
to change either; protocol/ is shared verbatim by the daemon and libfxclient, so it may include
only itself and system headers. Prints each cycle or stray include, then
"check_includes: N passed, M failed" (one check per rule); exits 1 on any failure.
Run from the repository root; make test runs it (tests/integration/test_includes.sh)."""
import glob
import os
import re
import sys

ROOTS = ("server", "protocol", "common", "clients/c", "kernels")
SEARCH = ("protocol", "common", "server", "clients/c", "kernels")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def sources():
    files = []
    for root in ROOTS:
        for ext in ("c", "h"):
            files += glob.glob(f"{root}/**/*.{ext}", recursive=True)
    return sorted(files)


def resolve(including, name):
    for d in (os.path.dirname(including),) + SEARCH:
        path = os.path.normpath(os.path.join(d, name))
        if os.path.isfile(path):
            return path
    return None  # a generated or system header


def graph(files):
    edges = {}
    for f in files:
        mod = os.path.splitext(f)[0]
        edges.setdefault(mod, set())
        for name in INCLUDE.findall(open(f, encoding="utf-8").read()):
            target = resolve(f, name)
            if target and os.path.splitext(target)[0] != mod:
                edges[mod].add(os.path.splitext(target)[0])
    return edges


def cycles(edges):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def main():
    files = sources()
    edges = graph(files)
    passed = failed = 0
    found = cycles(edges)
    for comp in found:
        print("include cycle: " + " <-> ".join(comp))
    if found:
        failed += 1
    else:
        passed += 1
    stray = [(m, t) for m, ts in sorted(edges.items()) if m.startswith("protocol/")
             for t in sorted(ts) if not t.startswith("protocol/")]
    for m, t in stray:
        print(f"protocol/ must stand alone: {m} includes {t}")
    if stray:
        failed += 1
    else:
        passed += 1
    print(f"  {len(files)} files, {len(edges)} modules, {sum(len(t) for t in edges.values())} dependencies")
    print(f"check_includes: {passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
