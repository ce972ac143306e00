#!/usr/bin/env python3
"""param_table.py — renders an effect's parameter table for protocol/PROTOCOL.md from its
`describe` reply (JSON on stdin, e.g. `build/fxctl describe energy_wave`), so the spec
cannot drift from the code.

  param_table.py EFFECT [--write FILE | --check FILE] < describe.json

The table lives between "<!-- generated: EFFECT parameters -->" and
"<!-- end of generated table -->" in FILE. --write replaces it; --check exits 1 (with a
diff) when it is out of date; with neither, the table goes to stdout."""
import difflib
import json
import sys


def cell(v):
    return json.dumps(v, separators=(",", ":"))


def rng(p):
    t = p["type"]
    if t == "enum":
        return " \\| ".join("`%s`" % c for c in p["choices"])
    if t == "bool":
        return "true \\| false"
    if t == "object_list":
        return "%d–%d items" % (p["min_len"], p["max_len"])
    lim = "[%g, %g]" % (p["min"], p["max"])
    if t in ("vec3", "color"):
        r = "3 × " + lim
    elif t == "float_list":
        r = "%d–%d × %s" % (p["min_len"], p["max_len"], lim)
    else:
        r = "%g … %g" % (p["min"], p["max"])
    if p.get("even"):
        r += ", even"
    if p.get("nonzero"):
        r += ", non-zero"
    return r


def esc(s):
    return s.replace("|", "\\|")


def default(p):
    d = p["default"]
    if p["type"] == "object_list" and d:
        return "%d items (see below)" % len(d)
    return "`%s`" % cell(d)


def render(effect, desc):
    out = ["<!-- generated: %s parameters -->" % effect,
           "| group | name | type | range | default | unit | update | doc |",
           "|---|---|---|---|---|---|---|---|"]
    lists = []
    for p in desc["params"]:
        out.append("| %s | `%s` | %s | %s | %s | %s | %s | %s |" % (
            p["group"], p["name"], p["type"], rng(p), default(p), p["unit"], p["update"], esc(p["doc"])))
        if p["type"] == "object_list":
            lists.append(p)
    if lists:
        out += ["", "Fields of the list items (a missing field takes the default shown):", "",
                "| field | type | range | default | unit | doc |", "|---|---|---|---|---|---|"]
        for p in lists:
            for f in p["fields"]:
                out.append("| `%s[].%s` | %s | %s | `%s` | %s | %s |" % (
                    p["name"], f["name"], f["type"], rng(f), cell(f["default"]), f["unit"], esc(f["doc"])))
        for p in lists:
            if p["default"]:
                out += ["", "Default `%s`: `%s`" % (p["name"], cell(p["default"]))]
    out.append("<!-- end of generated table -->")
    return "\n".join(out) + "\n"


def main():
    effect, mode = sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None
    table = render(effect, json.load(sys.stdin))
    if not mode:
        sys.stdout.write(table)
        return 0
    path = sys.argv[3]
    text = open(path).read()
    begin = "<!-- generated: %s parameters -->" % effect
    start = text.index(begin)
    end = text.index("<!-- end of generated table -->", start)
    end += len("<!-- end of generated table -->\n")
    current = text[start:end]
    if mode == "--check":
        if current == table:
            return 0
        sys.stdout.writelines(difflib.unified_diff(current.splitlines(True), table.splitlines(True),
                                                   path, "describe"))
        return 1
    open(path, "w").write(text[:start] + table + text[end:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
