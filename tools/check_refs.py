#!/usr/bin/env python3
"""check_refs.py — every "§N.N" reference to the protocol names a section of protocol/PROTOCOL.md.

A reference is to PROTOCOL.md when the nearest document named before it on its line is
PROTOCOL(.md), or when none is named and the file is not about a thesis (its first 20 lines
name no "digest" or "thesis": there, an unnamed § is the digest's). References after "digest",
"thesis" or "seed" are the digests' (../shared, outside this repository) and are not checked.
A list such as "§3.5.3, §4" keeps the document of its first item. Prints each stale reference
as FILE:LINE and ends with "check_refs: N passed, M failed"; exits 1 on any failure.
Run from the repository root; make test runs it (tests/integration/test_refs.sh)."""
import re
import subprocess
import sys

SKIP = ("node_modules/", "tests/fuzz/corpus/", "tests/data/", "package-lock.json")
DOC = re.compile(r"PROTOCOL(?:\.md)?|ARCHITECTURE\.md|README(?:\.md)?|[Dd]igest|[Tt]hesis|seed|RFC ?\d+")
REF = re.compile(r"§\s?(\d+(?:\.\d+)*)")


def sections(path="protocol/PROTOCOL.md"):
    """Section numbers of PROTOCOL.md's headings: "## 7. Binary frames" -> 7, "### 7.5 ..." -> 7.5."""
    out = set()
    for line in open(path, encoding="utf-8"):
        m = re.match(r"#+\s+(\d+(?:\.\d+)*)\.?\s", line)
        if m:
            out.add(m.group(1))
    return out


def protocol_refs(path, text):
    """(line number, section) of each reference to PROTOCOL.md in one file."""
    lines = text.split("\n")
    thesis_file = path != "protocol/PROTOCOL.md" and re.search(r"[Dd]igest|[Tt]hesis", "\n".join(lines[:20]))
    for n, line in enumerate(lines, 1):
        for m in REF.finditer(line):
            named = DOC.findall(line[:m.start()])
            if named:
                doc = named[-1]
            elif path == "protocol/PROTOCOL.md" or not thesis_file:
                doc = "PROTOCOL"
            else:
                doc = "digest"
            if doc.startswith("PROTOCOL"):
                yield n, m.group(1)
            elif doc.startswith(("ARCHITECTURE", "README")):
                yield n, "(" + doc + " has no numbered sections) " + m.group(1)


def main():
    known = sections()
    files = subprocess.run(["git", "ls-files"], capture_output=True, text=True, check=True).stdout.split()
    passed = failed = 0
    for path in files:
        if path.startswith(SKIP):
            continue
        try:
            text = open(path, encoding="utf-8").read()
        except (UnicodeDecodeError, OSError):
            continue
        for n, sec in protocol_refs(path, text):
            if sec in known:
                passed += 1
            else:
                failed += 1
                print("FAIL %s:%d: §%s is not a section of protocol/PROTOCOL.md" % (path, n, sec))
    print("check_refs: %d passed, %d failed" % (passed, failed))
    return 1 if failed or not passed else 0


if __name__ == "__main__":
    sys.exit(main())
