#!/usr/bin/env python3
"""check_includes.py — the layering of the C tree (server/, protocol/, common/, clients/c/ and
the kernels' layout headers), checked from its #include lines.

A module is a source file's path without its extension (server/hub.c and server/hub.h are one
module, server/hub). Module A depends on module B when A's .c or .h includes B's header, found
as the compiler finds it: next to the including file, then in protocol/, common/, server/,
clients/c/, kernels/ (the Makefile's -I order). Three rules, one check each:

1. No include cycles. A cycle among modules means a newcomer must hold both files in mind to
   change either; within fxload, fxctl, libfxclient or the daemon alike.
2. Layers. Each module belongs to the first layer of LAYERS whose pattern matches its path
   and may include only its own layer's modules and those of the layers listed with it:
     protocol/, common/, kernels/  nothing else (protocol/ is compiled into the daemon and
                                   libfxclient, common/ into the daemon and fxctl, a layout
                                   header is prepended to its kernel's OpenCL source)
     server/                       protocol/, common/, kernels/
     fxctl, fxload (clients/c)     libfxclient, protocol/, common/; never server/, nor each
                                   other
     clients/c/examples/           libfxclient, protocol/ (the installed API)
     libfxclient (the rest of      protocol/ (common/ is not compiled into the library)
       clients/c)
   so the daemon and the clients meet only in protocol/ and common/.
3. A header declares only functions its own module defines: its .c (where there is no STEM.c,
   the STEM_*.c files it is split into), inline in the header itself, or, for the interfaces
   in ELSEWHERE, the one file that implements them. So the include graph is the dependency
   graph: a header that declared the functions of several files (as fxload.h once did for
   seven) hides the cycles among them from rule 1.

Prints each cycle, stray include and foreign declaration, then "check_includes: N passed, M
failed"; exits 1 on any failure. Checks the repository it is in, or the tree given as its one
argument (tests/integration/test_includes.sh plants faults in a scratch tree); make test runs it."""
import fnmatch
import glob
import os
import re
import sys

ROOTS = ("server", "protocol", "common", "clients/c", "kernels")
SEARCH = ("protocol", "common", "server", "clients/c", "kernels")
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

# (layer, path patterns of its modules, the other layers it may include); first match wins.
LAYERS = (
    ("protocol", ("protocol/*",), ()),
    ("common", ("common/*",), ()),
    ("kernels", ("kernels/*",), ()),
    ("server", ("server/*",), ("protocol", "common", "kernels")),
    ("fxctl", ("clients/c/fxctl*", "clients/c/png"), ("libfxclient", "protocol", "common")),
    ("fxload", ("clients/c/fxload*",), ("libfxclient", "protocol", "common")),
    ("examples", ("clients/c/examples/*",), ("libfxclient", "protocol")),
    ("libfxclient", ("clients/c/*",), ("protocol",)),
)

# Headers whose functions another file defines: an interface and its one implementation
# (None: a generated file).
ELSEWHERE = {
    "server/effect.h": "server/effects/registry.c",
    "server/kernels.h": None,  # build/gen/kernels.c, written by tools/embed_kernels.sh
}

# Comments, string and character literals: blanked before declarations are read.
LEXEME = re.compile(r'/\*.*?\*/|//[^\n]*|"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'', re.S)
DIRECTIVE = re.compile(r'^\s*#(?:[^\n]*\\\n)*[^\n]*', re.M)
CALLED = re.compile(r'([A-Za-z_]\w*)\s*\(')
DEFINED = re.compile(r'([A-Za-z_]\w*)\s*\([^;{}]*\)\s*(?:__attribute__\s*\(\([^;{}]*\)\)\s*)?\{')


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


def layer_of(mod):
    for name, patterns, _ in LAYERS:
        if any(fnmatch.fnmatch(mod, p) for p in patterns):
            return name
    return None


def layer_faults(edges):
    allowed = {name: (name,) + others for name, _, others in LAYERS}
    faults = []
    for m, targets in sorted(edges.items()):
        lm = layer_of(m)
        if lm is None:
            faults.append(f"layers: {m} is in no layer of LAYERS")
            continue
        for t in sorted(targets):
            lt = layer_of(t)
            if lt is not None and lt not in allowed[lm]:
                faults.append(f"layers: {m} ({lm}) includes {t} ({lt}); {lm} may include only "
                              + ", ".join(allowed[lm]))
    return faults


def code(path):
    """The text of a C file with comments, literals and preprocessor lines blanked."""
    text = LEXEME.sub(lambda m: " " if m.group(0)[0] == "/" else "0", open(path, encoding="utf-8").read())
    return DIRECTIVE.sub(" ", text)


def declared_functions(header):
    """Names of the functions a header declares (not static, not a typedef or a pointer)."""
    text, depth, top = code(header), 0, []
    for ch in text:  # top-level text; a braced body ends a declaration like a semicolon
        if ch == "{":
            depth += 1
            top.append(";" if depth == 1 else "")
        elif ch == "}":
            depth -= 1
            top.append(";" if depth == 0 else "")
        elif depth == 0:
            top.append(ch)
    names = []
    for decl in " ".join("".join(top).split()).split(";"):
        m = CALLED.search(decl)
        if not m or re.match(r"\s*(typedef|static)\b", decl) or decl[m.end():].lstrip().startswith("*"):
            continue
        if m.group(1) != "__attribute__" and not re.search(r"\(\s*\*\s*$", decl[:m.start()]):
            names.append(m.group(1))
    return names


def declaration_faults(files):
    faults = []
    for h in (f for f in files if f.endswith(".h")):
        names = declared_functions(h)
        stem = os.path.splitext(h)[0]
        impl = ELSEWHERE.get(h, stem + ".c")
        if not names or (h in ELSEWHERE and impl is None):
            continue
        # the module: its .c (or, where there is none, the STEM_*.c files it is split into) and
        # the header's own inline definitions
        split = h not in ELSEWHERE and not os.path.isfile(impl)
        parts = sorted(glob.glob(stem + "_*.c")) if split else [impl]
        defined = set(DEFINED.findall(code(h)))
        for f in parts:
            if os.path.isfile(f):
                defined |= set(DEFINED.findall(code(f)))
        foreign = [n for n in names if n not in defined]
        if foreign:
            faults.append(f"declarations: {h} declares what {impl} does not define: " + ", ".join(foreign))
    return faults


def main(argv):
    os.chdir(argv[1] if len(argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    files = sources()
    edges = graph(files)
    faults = [
        ["include cycle: " + " <-> ".join(c) for c in cycles(edges)],
        layer_faults(edges),
        declaration_faults(files),
    ]
    for f in (f for rule in faults for f in rule):
        print(f)
    failed = sum(1 for rule in faults if rule)
    print(f"  {len(files)} files, {len(edges)} modules, {sum(len(t) for t in edges.values())} dependencies")
    print(f"check_includes: {len(faults) - failed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
