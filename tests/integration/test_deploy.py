"""test_deploy.py — offline checks of deploy/: the systemd unit, the Dockerfile and the
Kubernetes manifests, as far as this machine can check them without systemd as PID 1,
a Docker daemon or a cluster.

- systemd unit: `systemd-analyze verify` (on a copy whose ExecStart is the built binary;
  a copy with a misspelt key shows verify does complain); the hardening directives; and
  what the filters would meet: the daemon runs under strace with an empty PoCL kernel
  cache (so PoCL compiles, links with ld and dlopen()s a kernel) and serves frames, and
  every syscall it and its children make must be in @system-service, every socket family
  in RestrictAddressFamilies, and with MemoryDenyWriteExecute=yes no mapping may be made
  writable+executable or executable later (systemd's seccomp rules).
- Kubernetes: every object is checked against the API models of the official Kubernetes
  Python client (Debian's python3-kubernetes, generated from the Kubernetes OpenAPI spec):
  unknown fields, types, required fields; then the cross-references (selectors, ports,
  probes, volumes, config, annotations), and the ConfigMap's config is started for real.
- Dockerfile: parsed statically (no Docker daemon here): stages, packages, user, health
  check (whose command is run against a real daemon), volume, port, and every library the
  built binaries link to must come from a package the runtime stage installs.
Bounded: about 20 s, most of it PoCL compiling one kernel under strace."""
import copy
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import ROOT, Suite  # noqa: E402

DEPLOY = os.path.join(ROOT, "deploy")
K8S = os.path.join(DEPLOY, "k8s")
UNIT = os.path.join(DEPLOY, "fxstreamd.service")
DAEMON = os.path.join(ROOT, "build", "fxstreamd")
FXCTL = os.path.join(ROOT, "build", "fxctl")
TOKENS = "admin:deploy-test-token-0123456789"


def start_daemon(args, env=None, wrap=()):
    """Starts fxstreamd (optionally under a wrapper); returns (proc, port) or (proc, None)."""
    e = {k: v for k, v in os.environ.items() if k != "FXSTREAMD_TOKENS"}
    e.update(env or {})
    # Its own process group, so that stop() reaches the daemon under a wrapper too (strace
    # detaches on SIGTERM and the daemon would live on).
    proc = subprocess.Popen([*wrap, DAEMON, "--listen", "127.0.0.1", "--port", "0", "--log-level", "warn", *args],
                            stdout=subprocess.PIPE, stderr=tempfile.TemporaryFile(), text=True, env=e,
                            start_new_session=True)
    line = proc.stdout.readline()
    if "listening on" not in line:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        return proc, None
    return proc, int(line.split("127.0.0.1:")[1].split("/")[0])


def stop(proc):
    """SIGTERM to the daemon and its wrapper (the whole group), SIGKILL after 15 s."""
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    except ProcessLookupError:
        proc.wait()


# ---- systemd ----------------------------------------------------------------------------

def unit_directives(text):
    d = {}
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith(("#", ";", "[")) and "=" in line:
            k, v = line.split("=", 1)
            d.setdefault(k.strip(), []).append(v.strip())
    return d


def verify_unit(text):
    """systemd-analyze verify on a copy of the unit; returns everything it printed."""
    d = tempfile.mkdtemp(prefix="fxs-unit-")
    try:
        path = os.path.join(d, "fxstreamd.service")
        with open(path, "w") as f:
            f.write(text)
        r = subprocess.run(["systemd-analyze", "verify", path], capture_output=True, text=True, timeout=60)
        return r.returncode, (r.stdout + r.stderr).strip()
    finally:
        shutil.rmtree(d, ignore_errors=True)


def syscall_group(name, seen=None):
    """The syscalls of a systemd filter group, sub-groups expanded."""
    seen = seen if seen is not None else set()
    if name in seen:
        return set()
    seen.add(name)
    out = subprocess.run(["systemd-analyze", "syscall-filter", name], capture_output=True, text=True,
                         timeout=30).stdout
    calls = set()
    for line in out.splitlines()[1:]:
        w = line.strip().split()
        if not w or w[0].startswith("#"):
            continue
        calls |= syscall_group(w[0], seen) if w[0].startswith("@") else {w[0]}
    return calls


def test_unit(t):
    text = open(UNIT).read()
    d = unit_directives(text)
    exec_start = d.get("ExecStart", [""])[0]
    t.check(exec_start.startswith("/usr/local/bin/fxstreamd --config /usr/local/etc/fxstream/fxstreamd.json"),
            "unit starts the installed binary with the installed config")
    rc, out = verify_unit(text.replace(exec_start.split()[0], DAEMON, 1))
    t.check(rc == 0 and out == "", "systemd-analyze verify: no complaint" + ("" if not out else ": " + out[-400:]))
    rc, out = verify_unit(text.replace(exec_start.split()[0], DAEMON, 1).replace("PrivateTmp=", "PrivatTmp="))
    t.check("PrivatTmp" in out, "systemd-analyze verify does complain about a misspelt key")
    want = {"DynamicUser": "yes", "ProtectSystem": "strict", "StateDirectory": "fxstream", "Restart": "on-failure",
            "NoNewPrivileges": "yes", "PrivateTmp": "yes", "ProtectHome": "yes", "CapabilityBoundingSet": "",
            "SystemCallFilter": "@system-service"}
    wrong = {k: d.get(k) for k, v in want.items() if d.get(k) != [v]}
    t.check(not wrong, "hardening directives present %s" % (wrong or ""))
    t.check("RestrictAddressFamilies" in d, "RestrictAddressFamilies is set")
    cfg = json.load(open(os.path.join(DEPLOY, "fxstreamd.json")))
    t.check(cfg.get("state_dir") == "/var/lib/" + d.get("StateDirectory", ["?"])[0],
            "the example config's state_dir is the unit's StateDirectory")
    t.check(any(e.startswith("POCL_CACHE_DIR=/var/cache/" + d.get("CacheDirectory", ["?"])[0])
                for e in d.get("Environment", [])), "PoCL's kernel cache lives in the unit's CacheDirectory")


def test_unit_filters(t):
    """What the daemon really does against the unit's syscall, family and W^X filters."""
    d = unit_directives(open(UNIT).read())
    strace = shutil.which("strace")
    if not t.check(strace is not None, "strace is installed (deploy/install-deps.sh)"):
        return
    tmp = tempfile.mkdtemp(prefix="fxs-strace-")
    trace = os.path.join(tmp, "trace")
    cfg = os.path.join(tmp, "c.json")
    with open(cfg, "w") as f:
        json.dump({"streams": [{"stream": "e", "effect": "energy_wave", "params": {"width": 64, "height": 48}}]}, f)
    proc, port = start_daemon(["--config", cfg, "--state-dir", tmp + "/state"],
                              env={"POCL_CACHE_DIR": tmp + "/pocl"},  # empty: PoCL must compile and link
                              wrap=(strace, "-f", "-qq", "-s", "256", "-o", trace))
    try:
        if not t.check(port is not None, "daemon starts under strace"):
            return
        r = subprocess.run([FXCTL, "--url", "ws://127.0.0.1:%d/v1/ws" % port, "--timeout", "40000",
                            "subscribe", "e", "--frames", "2"], capture_output=True, text=True, timeout=60)
        t.check(r.returncode == 0 and r.stdout.count('"seq"') == 2, "frames computed under strace")
    finally:
        stop(proc)
    lines = open(trace).read().splitlines() if os.path.exists(trace) else []
    shutil.rmtree(tmp, ignore_errors=True)
    t.check(any("execve(" in ln and "/ld" in ln for ln in lines) and
            any(re.search(r'openat\(.*pocl/.*\.so"', ln) for ln in lines),
            "the trace covers PoCL compiling, linking (ld) and loading a kernel")
    used = set()
    for ln in lines:
        m = re.match(r"\d+\s+([a-z_0-9]+)\(", ln) or re.match(r"\d+\s+<\.\.\. ([a-z_0-9]+) resumed>", ln)
        if m:
            used.add(m.group(1))
    allowed = set()
    for g in d.get("SystemCallFilter", [""])[0].split():
        allowed |= syscall_group(g) if g.startswith("@") else {g}
    t.check(len(used) > 20 and not (used - allowed),
            "every syscall (%d kinds) is in SystemCallFilter %s" % (len(used), sorted(used - allowed)))
    fams = {m.group(1) for ln in lines for m in [re.search(r"\bsocket\((AF_[A-Z0-9]+)", ln)] if m}
    allowed_f = set(d.get("RestrictAddressFamilies", [""])[0].split())
    t.check(fams and fams <= allowed_f, "socket families %s within RestrictAddressFamilies" % sorted(fams))
    wx = [ln for ln in lines if re.search(r"\bmmap\(.*PROT_WRITE\|PROT_EXEC|\bmmap\(.*PROT_EXEC\|PROT_WRITE", ln) or
          re.search(r"\b(pkey_)?mprotect\(.*PROT_EXEC", ln) or re.search(r"\bshmat\(.*SHM_EXEC", ln)]
    if d.get("MemoryDenyWriteExecute") == ["yes"]:
        t.check(not wx, "MemoryDenyWriteExecute=yes: nothing made writable+executable %s" % wx[:2])
    else:
        t.check(bool(wx), "MemoryDenyWriteExecute is off, and the trace shows why %s" % wx[:1])


# ---- Kubernetes -------------------------------------------------------------------------

KINDS = {("v1", "ConfigMap"): "V1ConfigMap", ("v1", "Service"): "V1Service",
         ("apps/v1", "StatefulSet"): "V1StatefulSet", ("policy/v1", "PodDisruptionBudget"): "V1PodDisruptionBudget",
         ("networking.k8s.io/v1", "Ingress"): "V1Ingress"}


def k8s_errors(obj):
    """Structural errors of one object against the Kubernetes client's models."""
    import kubernetes.client
    from kubernetes.client import models
    errs = []

    def walk(v, typ, path):
        if typ.startswith("list["):
            if not isinstance(v, list):
                return errs.append("%s: expected a list" % path)
            for i, x in enumerate(v):
                walk(x, typ[5:-1], "%s[%d]" % (path, i))
        elif typ.startswith("dict("):
            if not isinstance(v, dict):
                return errs.append("%s: expected a map" % path)
            inner = typ[5:-1].split(", ", 1)[1]
            for k, x in v.items():
                walk(x, inner, "%s.%s" % (path, k))
        elif typ in ("str", "datetime", "date"):
            if not isinstance(v, str):
                errs.append("%s: expected a string, got %r" % (path, v))
        elif typ == "int":
            if not isinstance(v, int) or isinstance(v, bool):
                errs.append("%s: expected an integer, got %r" % (path, v))
        elif typ == "bool":
            if not isinstance(v, bool):
                errs.append("%s: expected true/false, got %r" % (path, v))
        elif typ == "float":
            if not isinstance(v, (int, float)) or isinstance(v, bool):
                errs.append("%s: expected a number" % path)
        elif typ == "object":
            pass  # IntOrString, quantities, raw extensions
        else:
            cls = getattr(models, typ)
            if not isinstance(v, dict):
                return errs.append("%s: expected an object (%s)" % (path, typ))
            fields = {j: p for p, j in cls.attribute_map.items()}
            for k, x in v.items():
                if k not in fields:
                    errs.append("%s: unknown field %r in %s" % (path, k, typ))
                else:
                    walk(x, cls.openapi_types[fields[k]], "%s.%s" % (path, k))

    typ = KINDS.get((obj.get("apiVersion"), obj.get("kind")))
    if not typ:
        return ["unknown apiVersion/kind %s/%s" % (obj.get("apiVersion"), obj.get("kind"))]
    walk(obj, typ, obj["kind"])
    if not errs:  # required fields and enum setters: the models' own client-side validation
        try:
            kubernetes.client.ApiClient()._ApiClient__deserialize(copy.deepcopy(obj), typ)
        except (ValueError, TypeError) as e:
            errs.append("%s: %s" % (obj["kind"], e))
    return errs


def load_manifests():
    docs = []
    for f in sorted(os.listdir(K8S)):
        if f.endswith(".yaml") and f != "kustomization.yaml":
            for doc in yaml.safe_load_all(open(os.path.join(K8S, f))):
                if doc:
                    docs.append((f, doc))
    return docs


def test_k8s_schema(t):
    docs = load_manifests()
    kinds = sorted(d["kind"] for _, d in docs)
    t.check(kinds == ["ConfigMap", "Ingress", "PodDisruptionBudget", "Service", "Service", "StatefulSet"],
            "manifests: ConfigMap, Ingress, PodDisruptionBudget, 2 Services, StatefulSet (%s)" % kinds)
    bad = {"%s %s" % (f, d["kind"]): e for f, d in docs for e in [k8s_errors(d)] if e}
    t.check(not bad, "every object matches the Kubernetes API models %s" % (bad or ""))
    sts = next(d for _, d in docs if d["kind"] == "StatefulSet")
    broken = copy.deepcopy(sts)
    c = broken["spec"]["template"]["spec"]["containers"][0]
    c["livenessProbe"]["httpGet"]["paht"] = c["livenessProbe"]["httpGet"].pop("path")
    c["resources"]["limits"] = ["cpu"]
    e1 = k8s_errors(broken)
    broken2 = copy.deepcopy(sts)
    del broken2["spec"]["selector"]
    e2 = k8s_errors(broken2)
    t.check(any("paht" in e for e in e1) and any("limits" in e for e in e1) and any("selector" in e for e in e2),
            "the model check catches an unknown field, a wrong type and a missing required field")
    kust = yaml.safe_load(open(os.path.join(K8S, "kustomization.yaml")))
    files = sorted(f for f in os.listdir(K8S) if f.endswith(".yaml") and f != "kustomization.yaml")
    t.check(sorted(kust.get("resources", [])) == files, "kustomization.yaml lists every manifest")
    kubectl = shutil.which("kubectl")
    if kubectl:  # not from Debian; used when the machine has it
        r = subprocess.run([kubectl, "kustomize", K8S], capture_output=True, text=True, timeout=60)
        t.check(r.returncode == 0 and len([d for d in yaml.safe_load_all(r.stdout) if d]) == len(docs),
                "kubectl kustomize renders all %d objects" % len(docs))


def test_k8s_wiring(t):
    docs = load_manifests()
    by = {}
    for _, d in docs:
        by.setdefault(d["kind"], []).append(d)
    sts, cm, pdb, ing = by["StatefulSet"][0], by["ConfigMap"][0], by["PodDisruptionBudget"][0], by["Ingress"][0]
    svcs = {s["metadata"]["name"]: s for s in by["Service"]}
    pod = sts["spec"]["template"]
    labels = pod["metadata"]["labels"]
    matches = lambda sel: sel and all(labels.get(k) == v for k, v in sel.items())  # noqa: E731
    t.check(matches(sts["spec"]["selector"]["matchLabels"]), "StatefulSet selector matches its pod labels")
    head = svcs.get(sts["spec"]["serviceName"], {})
    t.check(head.get("spec", {}).get("clusterIP") == "None", "serviceName is a headless Service")
    t.check(all(matches(s["spec"]["selector"]) for s in svcs.values()) and matches(pdb["spec"]["selector"]["matchLabels"]),
            "Services and the PodDisruptionBudget select the daemon pods")
    c = pod["spec"]["containers"][0]
    ports = {p["name"]: p["containerPort"] for p in c["ports"]}
    t.check(all(p["targetPort"] in ports for s in svcs.values() for p in s["spec"]["ports"]),
            "Service targetPorts name a container port")
    cfg_text = cm["data"]["fxstreamd.json"]
    cfg = json.loads(cfg_text)
    t.check(cfg.get("port") in ports.values() and cfg.get("listen") == "0.0.0.0",
            "the daemon listens on all addresses on the container port")
    probes = [c.get(p, {}).get("httpGet", {}) for p in ("livenessProbe", "readinessProbe", "startupProbe")]
    t.check(all(p.get("path") == "/healthz" and p.get("port") in ports for p in probes),
            "liveness, readiness and startup probes ask /healthz")
    res = c.get("resources", {})
    t.check(all(k in res.get(w, {}) for w in ("requests", "limits") for k in ("cpu", "memory")),
            "resource requests and limits for cpu and memory")
    ann = pod["metadata"].get("annotations", {})
    t.check(ann.get("prometheus.io/scrape") == "true" and ann.get("prometheus.io/path") == "/metrics" and
            int(ann.get("prometheus.io/port", 0)) in ports.values(), "Prometheus scrape annotations per pod")
    mounts = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
    claims = {v["metadata"]["name"] for v in sts["spec"].get("volumeClaimTemplates", [])}
    t.check(mounts.get(cfg.get("state_dir")) in claims, "the config's state_dir is on the pod's PersistentVolumeClaim")
    vols = {v["name"]: v for v in pod["spec"]["volumes"]}
    conf_path = c["args"][c["args"].index("--config") + 1]
    conf_vol = vols.get(mounts.get(os.path.dirname(conf_path)), {})
    t.check(conf_vol.get("configMap", {}).get("name") == cm["metadata"]["name"] and
            os.path.basename(conf_path) in cm["data"], "--config is the ConfigMap's file")
    env = {e["name"]: e for e in c.get("env", [])}
    t.check("secretKeyRef" in env.get("FXSTREAMD_TOKENS", {}).get("valueFrom", {}),
            "tokens come from a Secret, not from the manifests")
    t.check(mounts.get("/var/cache/fxstream") and env.get("POCL_CACHE_DIR", {}).get("value", "").startswith(
        "/var/cache/fxstream") and c["securityContext"].get("readOnlyRootFilesystem") is True,
        "read-only root filesystem, PoCL's cache on a writable volume")
    sc = pod["spec"].get("securityContext", {})
    uid = re.search(r"--uid (\d+)", open(os.path.join(DEPLOY, "Dockerfile")).read())
    t.check(sc.get("runAsNonRoot") is True and uid and sc.get("runAsUser") == int(uid.group(1)) and
            sc.get("fsGroup") == int(uid.group(1)), "pods run as the image's non-root user; the PVC is theirs")
    a = ing["metadata"].get("annotations", {})
    conf = open(os.path.join(DEPLOY, "nginx", "fxstream.conf")).read()
    key = re.search(r"hash (\S+) consistent;", conf)
    t.check(a.get("nginx.ingress.kubernetes.io/upstream-hash-by") == "$arg_stream" and key and
            key.group(1) == "$arg_stream", "ingress hashes on $arg_stream, like deploy/nginx/fxstream.conf")
    t.check(int(a.get("nginx.ingress.kubernetes.io/proxy-read-timeout", 0)) >= 3600,
            "ingress keeps quiet WebSockets open (read timeout >= 1 h)")
    backends = [p["backend"]["service"] for r in ing["spec"]["rules"] for p in r["http"]["paths"]]
    t.check(all(b["name"] in svcs and b["port"].get("name") in [p["name"] for p in svcs[b["name"]]["spec"]["ports"]]
                for b in backends), "ingress backends name a Service and its port")
    # The ConfigMap's and the example's configurations, started for real (web root: the
    # tree's, which the image installs to the configured path).
    tmp = tempfile.mkdtemp(prefix="fxs-k8scfg-")
    try:
        for name, text in (("ConfigMap fxstreamd.json", cfg_text), ("deploy/fxstreamd.json",
                                                                     open(os.path.join(DEPLOY, "fxstreamd.json")).read())):
            path = os.path.join(tmp, "c.json")
            with open(path, "w") as f:
                f.write(text)
            args = ["--config", path, "--state-dir", tmp + "/state", "--web-root", os.path.join(ROOT, "clients", "web")]
            proc, port = start_daemon(args, env={"FXSTREAMD_TOKENS": TOKENS})
            stop(proc)
            t.check(port is not None, "the daemon accepts the %s" % name)
            r = subprocess.run([DAEMON, *args], capture_output=True,
                               text=True, timeout=30, env={k: v for k, v in os.environ.items() if k != "FXSTREAMD_TOKENS"})
            t.check(r.returncode == 2 and "token" in r.stderr, "the %s without tokens is refused" % name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


# ---- Dockerfile -------------------------------------------------------------------------

def dockerfile_stages(path):
    """[(from_line, [(INSTRUCTION, args)])] with continuation lines joined."""
    stages, cur, buf = [], None, ""
    for line in open(path).read().splitlines():
        if line.lstrip().startswith("#") and not buf:
            continue
        if line.rstrip().endswith("\\"):
            buf += line.rstrip()[:-1] + " "
            continue
        line, buf = buf + line, ""
        if not line.strip():
            continue
        ins, _, args = line.strip().partition(" ")
        ins = ins.upper()
        if ins == "FROM":
            cur = (args.strip(), [])
            stages.append(cur)
        elif cur:
            cur[1].append((ins, args.strip()))
    return stages


def apt_packages(stage):
    pkgs = []
    for ins, args in stage[1]:
        if ins == "RUN":
            for m in re.finditer(r"apt-get install ([^&;]*)", args):
                pkgs += [w for w in m.group(1).split() if not w.startswith("-")]
    return pkgs


def test_dockerfile(t):
    path = os.path.join(DEPLOY, "Dockerfile")
    stages = dockerfile_stages(path)
    t.check(len(stages) == 2 and all(re.match(r"debian:12(-slim)?\b", s[0]) for s in stages) and
            stages[0][0].endswith("AS build"), "two stages on Debian 12, the first named build")
    build, run = stages
    bp, rp = apt_packages(build), apt_packages(run)
    t.check(any(p.endswith("-dev") for p in bp) and "npm" in bp and "pocl-opencl-icd" not in bp,
            "build stage: -dev packages and npm")
    bruns = " ".join(a for i, a in build[1] if i == "RUN")
    t.check("npm ci" in bruns and "make" in bruns and "install" in bruns and "DESTDIR=" in bruns,
            "build stage: npm ci from the lock file, make, make install into a staging dir")
    t.check("pocl-opencl-icd" in rp and not [p for p in rp if p.endswith("-dev") or p in ("npm", "nodejs",
                                                                                       "build-essential")],
            "runtime stage: PoCL and libraries only %s" % rp)
    runs = [a for i, a in build[1] + run[1] if i == "RUN" and "apt-get install" in a]
    t.check(runs and all("--no-install-recommends" in a and "rm -rf /var/lib/apt/lists" in a for a in runs),
            "apt-get with --no-install-recommends, lists removed in the same layer")
    # Every library the programs link to directly comes from a package the runtime installs.
    need = set()
    for b in ("fxstreamd", "fxctl", "fxload"):
        exe = os.path.join(ROOT, "build", b)
        sonames = re.findall(r"\(NEEDED\).*\[(.+)\]", subprocess.run(["readelf", "-d", exe], capture_output=True,
                                                                        text=True).stdout)
        ldd = dict(re.findall(r"^\s*(\S+) => (\S+)", subprocess.run(["ldd", exe], capture_output=True,
                                                                      text=True).stdout, re.M))
        for so in sonames:
            real = os.path.realpath(ldd.get(so, so))
            r = subprocess.run(["dpkg", "-S", real], capture_output=True, text=True)
            if r.returncode:
                r = subprocess.run(["dpkg", "-S", ldd.get(so, so)], capture_output=True, text=True)
            need.add(r.stdout.split(":")[0] if r.returncode == 0 else "?" + so)
    missing = sorted(need - set(rp) - {"libc6"})
    t.check(need and not missing, "runtime stage installs every linked library's package %s (missing %s)" %
            (sorted(need), missing))
    lists = os.path.isdir("/var/lib/apt/lists") and any("_Packages" in f for f in os.listdir("/var/lib/apt/lists"))
    if lists:  # names exist in this Debian 12 machine's package index
        out = subprocess.run(["apt-cache", "policy", *bp, *rp], capture_output=True, text=True, timeout=60).stdout
        known = {m.group(1) for m in re.finditer(r"^(\S+):\n\s+Installed: .*\n\s+Candidate: (?!\(none\))", out, re.M)}
        unknown = sorted(set(bp + rp) - known)
        t.check(not unknown, "every apt package named is in Debian 12's index %s" % unknown)
    ins = {}
    for i, a in run[1]:
        ins.setdefault(i, []).append(a)
    user = ins.get("USER", ["root"])[-1].split(":")[0]
    t.check(user not in ("root", "0") and re.search(r"useradd[^&]*\b%s\b" % re.escape(user), " ".join(ins["RUN"])),
            "runs as a non-root user created in the image (%s)" % user)
    cfg = json.load(open(os.path.join(DEPLOY, "fxstreamd.json")))
    t.check(str(cfg["port"]) in " ".join(ins.get("EXPOSE", [])), "EXPOSE the configured port")
    t.check(cfg["state_dir"] in " ".join(ins.get("VOLUME", [])), "the state dir is a VOLUME")
    t.check(any("--from=build" in a for a in ins.get("COPY", [])), "the runtime copies the build stage's install")
    ep = json.loads(ins.get("ENTRYPOINT", ["[]"])[-1]) + json.loads(ins.get("CMD", ["[]"])[-1])
    copied = " ".join(ins.get("COPY", []))
    t.check(ep[:1] == ["/usr/local/bin/fxstreamd"] and "--config" in ep and
            ep[ep.index("--config") + 1] in copied, "starts the installed daemon with the copied config")
    t.check(re.search(r"web_root\W+/usr/local/share/fxstream/web", open(os.path.join(DEPLOY, "fxstreamd.json")).read())
            and "/usr/local/share/fxstream/" in copied, "the config's web root is the copied web client")
    hc = ins.get("HEALTHCHECK", [""])[-1]
    m = re.search(r"CMD (\[.*\])\s*$", hc)
    cmd = json.loads(m.group(1)) if m else []
    t.check("/healthz" in " ".join(cmd), "HEALTHCHECK asks /healthz")
    ignore = open(os.path.join(DEPLOY, "Dockerfile.dockerignore")).read().split()
    t.check(all(x in ignore for x in ("node_modules", "build", ".git")), "build outputs stay out of the context")
    # The health check's own command against a real daemon, and against nothing.
    tmp = tempfile.mkdtemp(prefix="fxs-hc-")
    proc, port = start_daemon(["--config", os.path.join(DEPLOY, "fxstreamd.json"), "--state-dir", tmp,
                               "--web-root", os.path.join(ROOT, "clients", "web")], env={"FXSTREAMD_TOKENS": TOKENS})
    try:
        run_hc = lambda p: subprocess.run([x.replace("7681", str(p)) for x in cmd], capture_output=True,  # noqa: E731
                                          timeout=10).returncode
        t.check(port is not None and cmd and run_hc(port) == 0, "the HEALTHCHECK command passes on a live daemon")
    finally:
        stop(proc)
        shutil.rmtree(tmp, ignore_errors=True)
    t.check(cmd and run_hc(port) != 0, "and fails when the daemon is gone")


def main():
    t = Suite("test_deploy")
    t0 = time.monotonic()
    for test in (test_unit, test_unit_filters, test_k8s_schema, test_k8s_wiring, test_dockerfile):
        t1 = time.monotonic()
        try:
            test(t)
        except Exception as e:
            t.check(False, "%s raised %s: %s" % (test.__name__, type(e).__name__, e))
        print("     (%s: %.1f s)" % (test.__name__, time.monotonic() - t1))
    print("(%.1f s)" % (time.monotonic() - t0))
    print("%s: %d passed, %d failed" % (t.name, t.passed, t.failed))
    sys.exit(1 if t.failed else 0)


if __name__ == "__main__":
    main()
