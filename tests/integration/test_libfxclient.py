"""test_libfxclient.py — libfxclient taken as a program outside the tree takes it.
`make install DESTDIR=D` puts the shared library (soname, version, symlinks), the
static one, the headers and fxclient.pc in place; pkg-config pointed at D (PKG_CONFIG_LIBDIR,
PKG_CONFIG_SYSROOT_DIR) gives flags into D only; the shared library exports fxclient.h's
FXC_API functions and nothing else; the header compiles as C99 and as C++. Built from those
installed files alone: clients/c/examples/flame_count.c subscribes to a real daemon's flame
and prints particle counts that match the frame headers, with nothing on stderr (quiet by
default; clean under valgrind), linked to the shared library and to the static one; the static library links into
a shared object (a game plugin needs position-independent code); README's smallest program
compiles and runs; tests/integration/fxc_api_check.c checks the API call by call."""
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import ROOT, Daemon, Suite  # noqa: E402

EXAMPLE = os.path.join(ROOT, "clients", "c", "examples", "flame_count.c")
API_CHECK = os.path.join(ROOT, "tests", "integration", "fxc_api_check.c")
LINE = re.compile(r"^flame frame (\d+): (\d+) particles \(header count (\d+)\), (\d+) burning, mean (\d+) K$")


def run(cmd, timeout=120, **kw):
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, **kw)


class Installed:
    """`make install DESTDIR=...` into a scratch directory, and pkg-config pointed there."""

    def __init__(self):
        self.dest = tempfile.mkdtemp(prefix="fxs-libfxclient-")
        self.make = run(["make", "--no-print-directory", "-C", ROOT, "install", "DESTDIR=" + self.dest], timeout=300)
        self.lib = self.dest + "/usr/local/lib"
        self.inc = self.dest + "/usr/local/include/fxclient"
        self.env = dict(os.environ, PKG_CONFIG_LIBDIR=self.lib + "/pkgconfig", PKG_CONFIG_PATH="",
                        PKG_CONFIG_SYSROOT_DIR=self.dest)
        self.version = re.search(r'#define FXC_VERSION "([0-9.]+)"', open(self.inc + "/fxclient.h").read()).group(1) \
            if self.make.returncode == 0 else "?"

    def pkg(self, *args):
        r = run(["pkg-config", *args, "fxclient"], env=self.env)
        return r.stdout.split() if r.returncode == 0 else None

    def cc(self, src, out, *extra, cc="cc", std="-std=c99", link=None):
        """Compiles src with the installed flags (link: the link flags, shared by default)."""
        flags = self.pkg("--cflags") + (link if link is not None else self.pkg("--libs"))
        return run([cc, std, "-Wall", "-Wextra", "-Werror", "-pedantic", src, "-o", out, *extra, *flags])

    def rm(self):
        shutil.rmtree(self.dest, ignore_errors=True)


def check_files(t, ins):
    major = ins.version.split(".")[0]
    so = "libfxclient.so." + ins.version
    t.check(os.path.isfile(ins.lib + "/" + so) and not os.path.islink(ins.lib + "/" + so) and
            os.readlink(ins.lib + "/libfxclient.so." + major) == so and
            os.readlink(ins.lib + "/libfxclient.so") == "libfxclient.so." + major,
            "PREFIX/lib: %s, libfxclient.so.%s -> it, libfxclient.so -> that" % (so, major))
    t.check(os.path.isfile(ins.lib + "/libfxclient.a"), "PREFIX/lib/libfxclient.a")
    t.check(sorted(os.listdir(ins.inc)) == ["fxclient.h", "fxs_bytes.h", "fxs_frame.h"],
            "PREFIX/include/fxclient: fxclient.h and the two headers it includes")
    pc = open(ins.lib + "/pkgconfig/fxclient.pc").read()
    t.check("Version: %s\n" % ins.version in pc, "fxclient.pc has the header's version %s" % ins.version)
    d = run(["readelf", "-d", ins.lib + "/" + so]).stdout
    t.check("Library soname: [libfxclient.so.%s]" % major in d, "the soname is libfxclient.so.%s" % major)
    exported = set(run(["nm", "-D", "--defined-only", "--format=just-symbols", ins.lib + "/" + so]).stdout.split())
    declared = set(re.findall(r"FXC_API[^;(]*?\b(fxc_\w+)\s*\(", open(ins.inc + "/fxclient.h").read()))
    t.check(declared and exported == declared,
            "the shared library exports the %d FXC_API functions and nothing else (extra %s, missing %s)" %
            (len(declared), sorted(exported - declared)[:5], sorted(declared - exported)[:5]))


def check_pkgconfig(t, ins, tmp):
    cflags, libs = ins.pkg("--cflags"), ins.pkg("--libs")
    t.check(cflags == ["-I" + ins.inc] and libs == ["-L" + ins.lib, "-lfxclient"],
            "pkg-config --cflags --libs fxclient: the installed tree only (%s %s)" % (cflags, libs))
    static = ins.pkg("--static", "--libs") or []
    t.check(all(f in static for f in ("-lwebsockets", "-lcjson", "-lzstd", "-lm")),
            "pkg-config --static names what the static library needs: %s" % " ".join(static))
    src = os.path.join(tmp, "only_header.c")
    with open(src, "w") as f:
        f.write("#include <fxclient.h>\nint main(void) { return fxc_version()[0] == 0; }\n")
    r = ins.cc(src, os.path.join(tmp, "only_c"))
    t.check(r.returncode == 0, "the header compiles as C99 -pedantic -Werror and links " + r.stderr[-300:])
    r = ins.cc(src, os.path.join(tmp, "only_cxx"), "-x", "c++", cc="c++", std="-std=c++11")
    t.check(r.returncode == 0, "... and as C++11 " + r.stderr[-300:])


def frame_lines(out):
    return [LINE.match(l) for l in out.splitlines() if l.startswith("flame frame")]


def check_example(t, ins, tmp, daemon):
    exe = os.path.join(tmp, "flame_count")
    r = ins.cc(EXAMPLE, exe)
    if not t.check(r.returncode == 0, "flame_count.c builds from the installed files " + r.stderr[-400:]):
        return
    needed = run(["readelf", "-d", exe]).stdout
    t.check("Shared library: [libfxclient.so.%s]" % ins.version.split(".")[0] in needed,
            "it links the shared library by its soname")
    env = dict(os.environ, LD_LIBRARY_PATH=ins.lib)
    t0 = time.monotonic()
    r = run([exe, daemon.url, "10"], env=env, timeout=60)
    lines = frame_lines(r.stdout)
    ok = r.returncode == 0 and len(lines) == 10 and all(lines)
    t.check(ok, "it prints 10 flame frames and exits 0 (%.1f s)%s" % (
        time.monotonic() - t0, "" if ok else ": exit %d, %d lines: %s" % (r.returncode, len(lines), (r.stdout + r.stderr)[-600:])))
    t.check(lines and all(m and m.group(2) == m.group(3) and int(m.group(2)) > 0 for m in lines),
            "each frame's decoded count equals its header's: %s" % [m.group(2) for m in lines if m][:10])
    t.check(lines and all(m and 300 <= int(m.group(5)) <= 5000 for m in lines) and
            any(m and int(m.group(4)) > 0 for m in lines),
            "the decoded temperatures are a flame's (mean 300..5000 K, some particles burning)")
    t.check(r.stderr == "", "nothing on stderr: quiet by default, no libwebsockets banner (%r)" % r.stderr[:200])
    poll = re.search(r"longest fxc_poll call: ([0-9.]+) ms", r.stdout)
    print("info example's longest fxc_poll(..., 0, ...) call: %s ms (wall clock)" % (poll.group(1) if poll else "?"))
    r = run(["valgrind", "-q", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect", "--error-exitcode=9",
             exe, daemon.url, "5"], env=env, timeout=120)
    ok = r.returncode == 0 and len(frame_lines(r.stdout)) == 5 and r.stderr == ""
    t.check(ok, "under valgrind: no memory error, nothing leaked" + ("" if ok else ": exit %d %s" % (r.returncode, r.stderr[-800:])))
    r = run([exe, "ws://127.0.0.1:1/v1/ws", "1"], env=env, timeout=30)
    t.check(r.returncode == 1 and "connection refused by 127.0.0.1:1" in r.stderr,
            "against a closed port it says so and exits 1 (%s)" % r.stderr.strip())


def check_static(t, ins, tmp, daemon):
    exe = os.path.join(tmp, "flame_count_static")
    archive = ins.lib + "/libfxclient.a"
    r = ins.cc(EXAMPLE, exe, link=["-Wl,--as-needed", archive] + ins.pkg("--static", "--libs"))
    if not t.check(r.returncode == 0, "flame_count.c links the static library " + r.stderr[-400:]):
        return
    t.check("libfxclient" not in run(["readelf", "-d", exe]).stdout, "... and needs no libfxclient.so then")
    r = run([exe, daemon.url, "3"], timeout=60)
    t.check(r.returncode == 0 and len(frame_lines(r.stdout)) == 3 and r.stderr == "",
            "the static build runs without LD_LIBRARY_PATH " + r.stderr[-300:])
    plugin = os.path.join(tmp, "plugin.so")
    r = ins.cc(EXAMPLE, plugin, "-shared", "-fPIC", "-Wl,--no-undefined",
               link=[archive] + [f for f in ins.pkg("--static", "--libs-only-l") if f != "-lfxclient"])
    t.check(r.returncode == 0, "the static library links into a shared object (a game plugin) " + r.stderr[-400:])


def readme_program():
    """The C block of README's "C client library" section."""
    text = open(os.path.join(ROOT, "README.md")).read()
    section = text.split("\n## C client library\n", 1)[1].split("\n## ", 1)[0]
    return section.split("```c\n", 1)[1].split("```", 1)[0]


def check_readme(t, ins, tmp, daemon):
    src = os.path.join(tmp, "smallest.c")
    with open(src, "w") as f:
        f.write(readme_program())
    r = ins.cc(src, os.path.join(tmp, "smallest"))
    if not t.check(r.returncode == 0, "README's smallest program builds " + r.stderr[-400:]):
        return
    r = run([os.path.join(tmp, "smallest"), daemon.url], env=dict(os.environ, LD_LIBRARY_PATH=ins.lib), timeout=60)
    ok = r.returncode == 0 and len(re.findall(r"^flame frame \d+: \d+ particles$", r.stdout, re.M)) == 5
    t.check(ok, "... and prints 5 flame frames" + ("" if ok else ": " + (r.stdout + r.stderr)[-300:]))


def check_api(t, ins, tmp, daemon):
    exe = os.path.join(tmp, "fxc_api_check")
    r = ins.cc(API_CHECK, exe)
    if not t.check(r.returncode == 0, "fxc_api_check.c builds from the installed files " + r.stderr[-400:]):
        return
    r = run([exe, daemon.url, str(daemon.proc.pid)], env=dict(os.environ, LD_LIBRARY_PATH=ins.lib), timeout=180)
    for line in r.stdout.splitlines():
        if line.startswith(("ok   ", "FAIL ")):
            t.check(line.startswith("ok"), "api: " + line[5:])
        elif line.startswith("info"):
            print(line)
    cpu = re.search(r"([0-9.]+) ms CPU", r.stdout)
    t.check(cpu and float(cpu.group(1)) < 20,
            "api: no fxc_poll(..., 0, ...) took 20 ms of CPU (%s ms; FXC_POLL_BUDGET_US is 2 ms)" %
            (cpu.group(1) if cpu else "?"))
    t.check(r.returncode == 0 and r.stderr == "", "api: exit 0, nothing on stderr " + r.stderr[-300:])


def step(t, fn, *args):
    """Runs one group of checks; one that raises is a failed check and the suite goes on."""
    try:
        fn(t, *args)
    except Exception as e:
        t.check(False, "%s raised %s: %s" % (fn.__name__, type(e).__name__, e))


def main():
    t = Suite("test_libfxclient")
    t0 = time.monotonic()
    ins = Installed()
    tmp = tempfile.mkdtemp(prefix="fxs-libfxclient-build-")
    try:
        if t.check(ins.make.returncode == 0, "make install DESTDIR=%s %s" % (ins.dest, ins.make.stderr[-600:])):
            step(t, check_files, ins)
            step(t, check_pkgconfig, ins, tmp)
            with Daemon() as daemon:
                for fn in (check_example, check_static, check_readme, check_api):  # check_api stops the daemon
                    step(t, fn, ins, tmp, daemon)
    finally:
        ins.rm()
        shutil.rmtree(tmp, ignore_errors=True)
    print("(%.1f s)" % (time.monotonic() - t0))
    print("%s: %d passed, %d failed" % (t.name, t.passed, t.failed))
    sys.exit(1 if t.failed else 0)


if __name__ == "__main__":
    main()
