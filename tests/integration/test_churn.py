"""test_churn.py — thousands of connect, subscribe, disconnect cycles against the ASan and
UBSan build of fxstreamd (build/fz/fxstreamd, built by make with the fuzz targets): clean
closes and abrupt ones (the TCP connection dropped mid-frame), with no sanitizer report,
no leak at exit (LeakSanitizer; tests/integration/lsan.supp lists only the OpenCL stack),
memory flat after warm-up, and every connection accounted for; then fewer cycles against
the normal build under valgrind (no error, nothing definitely or indirectly lost;
tests/integration/valgrind.supp holds one glibc false positive).
Run from the repository root: /usr/bin/python3 tests/integration/test_churn.py"""
import asyncio
import os
import re
import urllib.request

from fxtest import ROOT, Client, Daemon, Suite, config_file

ASAN_DAEMON = os.path.join(ROOT, "build", "fz", "fxstreamd")
CYCLES, CONCURRENCY, WARM = 1500, 25, 300
VALGRIND_CYCLES = 200


def churn_config():
    return config_file({"streams": [{"stream": "small", "effect": "energy_wave",
                                     "params": {"width": 64, "height": 32, "fps": 60}}]})


def rss_kib(d):
    with open("/proc/%d/status" % d.proc.pid) as f:
        return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1))


def connections(d):
    with urllib.request.urlopen(d.http + "/metrics", timeout=10) as r:
        return float(re.search(r"^fxs_connections (\S+)$", r.read().decode(), re.M).group(1))


async def cycle(d, i, timeout=10):
    """One connect, subscribe, first frame, disconnect; each wait bounded by timeout s."""
    c = await Client.connect(d, timeout=timeout)
    if i % 5 == 0:
        await c.request("list", timeout=timeout)
        await c.request("get", stream="small", timeout=timeout)
    await c.request("subscribe", stream="small", timeout=timeout)
    await c.frame(3 * timeout)
    if i % 3 == 0:
        c.ws.transport.abort()  # gone without a close frame, maybe mid-frame
    else:
        await c.close()


async def test_churn(t):
    if not t.check(os.access(ASAN_DAEMON, os.X_OK), "the ASan daemon is built (%s)" % ASAN_DAEMON):
        return
    cfg = churn_config()
    env = {"ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:quarantine_size_mb=8",  # small quarantine: RSS says something
           "LSAN_OPTIONS": "suppressions=%s:print_suppressions=0" % os.path.join(ROOT, "tests/integration/lsan.supp"),
           "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1"}
    d = Daemon("--config", cfg, binary=ASAN_DAEMON, env=env)
    failures, done, rss = [], 0, {}
    try:
        sem = asyncio.Semaphore(CONCURRENCY)

        async def one(i):
            nonlocal done
            async with sem:
                try:
                    await cycle(d, i)
                except Exception as e:  # counted: every cycle must work
                    failures.append("%s: %s" % (type(e).__name__, e))
                done += 1
                if done == WARM:
                    rss["warm"] = rss_kib(d)

        await asyncio.gather(*(one(i) for i in range(CYCLES)))
        rss["end"] = rss_kib(d)
        t.check(not failures, "%d connect-subscribe-disconnect cycles, %d failed %s"
                % (CYCLES, len(failures), failures[:3]))
        growth = rss["end"] - rss["warm"]
        t.check(growth < 16 * 1024, "memory flat after warm-up: RSS +%d KiB over %d cycles" % (growth, CYCLES - WARM))
        for _ in range(50):
            if connections(d) == 0:
                break
            await asyncio.sleep(0.1)
        t.check(connections(d) == 0, "every connection is gone from /metrics")
    finally:
        status = d.stop(timeout=60)
    err = d.log()
    reports = re.findall(r"ERROR: (?:AddressSanitizer|LeakSanitizer)[^\n]*|runtime error:[^\n]*", err)
    t.check(status == 0, "SIGTERM: clean exit (%s)" % status)
    t.check(not reports, "no sanitizer report or leak at exit %s" % reports[:3])
    if reports:
        print(err[-3000:])


async def test_valgrind(t):
    supp = os.path.join(ROOT, "tests/integration/valgrind.supp")
    d = Daemon("--config", churn_config(), wrapper=[
        "valgrind", "--leak-check=full", "--errors-for-leak-kinds=definite,indirect", "--error-exitcode=99",
        "--suppressions=" + supp, "--num-callers=30"])
    failures = []
    try:
        # The first cycle builds the kernel under valgrind (tens of seconds on a busy machine):
        # a warm-up with a long bound, not a timed cycle. Then each wait gets 60 s: this
        # part checks memory, not speed (a cycle takes ~0.3 s under valgrind when idle).
        await cycle(d, 0, timeout=120)
        for i in range(1, VALGRIND_CYCLES + 1):
            try:
                await cycle(d, i, timeout=60)
            except Exception as e:
                failures.append("%s: %s" % (type(e).__name__, e))
        t.check(not failures, "%d cycles under valgrind, %d failed %s" % (VALGRIND_CYCLES, len(failures), failures[:3]))
    finally:
        status = d.stop(timeout=300)
    err = d.log()
    lost = re.search(r"definitely lost: ([\d,]+) bytes.*?indirectly lost: ([\d,]+) bytes", err, re.S)
    t.check(lost and lost.group(1) == "0" and lost.group(2) == "0",
            "valgrind: nothing definitely or indirectly lost (%s)" % (lost.group(0).replace("\n", " ") if lost else "?"))
    t.check(status == 0, "valgrind: no memory error, clean exit (status %s)" % status)
    if status != 0:
        print(err[-4000:])


if __name__ == "__main__":
    Suite("test_churn").run([test_churn, test_valgrind], timeout=900)
