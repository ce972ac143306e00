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
- Kubernetes, cluster mode (deploy/k8s/cluster/): the same model check of every object
  (autoscaling/v2 against the client's v2beta2 models: the same schema), then the wiring:
  selectors against pod labels (the client Service selects the edge pods only), --role per
  Deployment, node id from the pod name, the --cluster URL against the Redis Service, the
  Redis password Secret key everywhere it is used, the autoscaler's target and metrics,
  probes, security context. The Redis container's own command and configuration are run
  with this machine's redis-server (password, AOF with fsync always, the probe command).
  The daemon is not started in cluster mode here (roles are not merged yet): its ConfigMap
  is checked statically against the single-node one, which is started.
- systemd drop-in for cluster mode (deploy/fxstreamd-cluster.conf): verified together
  with the unit, and a copy without the ExecStart= reset is shown to be refused.
- nginx for cluster mode (deploy/nginx/fxstream-cluster.conf): nginx -t, and run in front
  of two (single-node) daemons: WebSockets naming one stream spread over both, and the
  fxs_connections gauge the autoscaler reads counts them.
- Dockerfile: parsed statically (no Docker daemon here): stages, packages, user, health
  check (whose command is run against a real daemon), volume, port, and every library the
  built binaries link to must come from a package the runtime stage installs.
Bounded: about 25 s, most of it PoCL compiling one kernel under strace."""
import copy
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import ROOT, Suite  # noqa: E402

DEPLOY = os.path.join(ROOT, "deploy")
K8S = os.path.join(DEPLOY, "k8s")
K8S_CLUSTER = os.path.join(K8S, "cluster")
DROPIN = os.path.join(DEPLOY, "fxstreamd-cluster.conf")
NGINX_CLUSTER = os.path.join(DEPLOY, "nginx", "fxstream-cluster.conf")
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
                            "subscribe", "e", "--frames", "2", "--kind", "2"], capture_output=True, text=True, timeout=60)
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
         ("networking.k8s.io/v1", "Ingress"): "V1Ingress", ("apps/v1", "Deployment"): "V1Deployment",
         # python3-kubernetes 22.6 predates autoscaling/v2 (Kubernetes 1.23), which promoted
         # v2beta2 with the same fields: its models check a v2 object.
         ("autoscaling/v2", "HorizontalPodAutoscaler"): "V2beta2HorizontalPodAutoscaler"}


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


def load_manifests(where=K8S):
    docs = []
    for f in sorted(os.listdir(where)):
        if f.endswith(".yaml") and f != "kustomization.yaml":
            for doc in yaml.safe_load_all(open(os.path.join(where, f))):
                if doc:
                    docs.append((f, doc))
    return docs


def kustomize_check(t, where, ndocs):
    kust = yaml.safe_load(open(os.path.join(where, "kustomization.yaml")))
    files = sorted(f for f in os.listdir(where) if f.endswith(".yaml") and f != "kustomization.yaml")
    t.check(sorted(kust.get("resources", [])) == files, "%s/kustomization.yaml lists every manifest" %
            os.path.relpath(where, ROOT))
    kubectl = shutil.which("kubectl")
    if kubectl:  # not from Debian; used when the machine has it
        r = subprocess.run([kubectl, "kustomize", where], capture_output=True, text=True, timeout=60)
        t.check(r.returncode == 0 and len([d for d in yaml.safe_load_all(r.stdout) if d]) == ndocs,
                "kubectl kustomize renders all %d objects of %s" % (ndocs, os.path.relpath(where, ROOT)))


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
    kustomize_check(t, K8S, len(docs))


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


# ---- Kubernetes, cluster mode -----------------------------------------------------------

def test_k8s_cluster_schema(t):
    docs = load_manifests(K8S_CLUSTER)
    kinds = sorted(d["kind"] for _, d in docs)
    want = sorted(["ConfigMap"] * 2 + ["Deployment"] * 2 + ["HorizontalPodAutoscaler", "Ingress"] +
                  ["PodDisruptionBudget"] * 2 + ["Service"] * 3 + ["StatefulSet"])
    t.check(kinds == want, "cluster manifests: 2 ConfigMaps, 2 Deployments, HPA, Ingress, 2 PDBs, 3 Services, "
            "Redis StatefulSet (%s)" % kinds)
    bad = {"%s %s" % (f, d["kind"]): e for f, d in docs for e in [k8s_errors(d)] if e}
    t.check(not bad, "every cluster object matches the Kubernetes API models %s" % (bad or ""))
    hpa = next(d for _, d in docs if d["kind"] == "HorizontalPodAutoscaler")
    broken = copy.deepcopy(hpa)
    broken["spec"]["metrics"][0]["pods"]["metrik"] = broken["spec"]["metrics"][0]["pods"].pop("metric")
    broken2 = copy.deepcopy(hpa)
    del broken2["spec"]["scaleTargetRef"]
    t.check(any("metrik" in e for e in k8s_errors(broken)) and any("scale_target_ref" in e or "scaleTargetRef" in e
                                                                   for e in k8s_errors(broken2)),
            "the model check catches an unknown field and a missing required field in the HPA")
    kustomize_check(t, K8S_CLUSTER, len(docs))


def pairs(args):
    """--flag value pairs of a container's args."""
    return {a: b for a, b in zip(args, args[1:]) if a.startswith("--")}


def secret_ref(env, name):
    r = env.get(name, {}).get("valueFrom", {}).get("secretKeyRef", {})
    return (r.get("name"), r.get("key")) if r else None


def test_k8s_cluster_wiring(t):
    docs = load_manifests(K8S_CLUSTER)
    by = {}
    for _, d in docs:
        by.setdefault(d["kind"], {})[d["metadata"]["name"]] = d
    deps, svcs, cms = by.get("Deployment", {}), by.get("Service", {}), by.get("ConfigMap", {})
    comp, edge = deps.get("fxstreamd-compute"), deps.get("fxstreamd-edge")
    redis = by.get("StatefulSet", {}).get("fxstream-redis")
    if not t.check(comp and edge and redis, "Deployments fxstreamd-compute, fxstreamd-edge, StatefulSet fxstream-redis"):
        return
    labels = {n: w["spec"]["template"]["metadata"]["labels"] for n, w in
              (("compute", comp), ("edge", edge), ("redis", redis))}
    matches = lambda sel, lab: bool(sel) and all(lab.get(k) == v for k, v in sel.items())  # noqa: E731
    selects = lambda sel: sorted(n for n, lab in labels.items() if matches(sel, lab))  # noqa: E731
    t.check(selects(comp["spec"]["selector"]["matchLabels"]) == ["compute"] and
            selects(edge["spec"]["selector"]["matchLabels"]) == ["edge"] and
            selects(redis["spec"]["selector"]["matchLabels"]) == ["redis"],
            "each workload's selector matches its own pods and no other's")
    client = svcs.get("fxstreamd", {})
    t.check(selects(client.get("spec", {}).get("selector")) == ["edge"] and
            client["spec"].get("type", "ClusterIP") == "ClusterIP" and "sessionAffinity" not in client["spec"],
            "Service fxstreamd: plain round robin over the edge pods only")
    rsvc = svcs.get("fxstream-redis", {})
    head = svcs.get(redis["spec"]["serviceName"], {})
    t.check(selects(rsvc.get("spec", {}).get("selector")) == ["redis"] and
            selects(head.get("spec", {}).get("selector")) == ["redis"] and head["spec"].get("clusterIP") == "None",
            "Redis Services select the Redis pod; the StatefulSet's serviceName is headless")
    pdbs = {n: selects(p["spec"]["selector"]["matchLabels"]) for n, p in by.get("PodDisruptionBudget", {}).items()}
    t.check(sorted(pdbs.values()) == [["compute"], ["edge"]], "one PodDisruptionBudget per Deployment %s" % pdbs)

    ports = {}
    for n, w in (("compute", comp), ("edge", edge), ("redis", redis)):
        ports[n] = {p["name"]: p["containerPort"] for p in w["spec"]["template"]["spec"]["containers"][0]["ports"]}
    t.check(all(p["targetPort"] in ports["edge"] for p in client["spec"]["ports"]) and
            all(p["targetPort"] in ports["redis"] for s in (rsvc, head) for p in s["spec"]["ports"]),
            "Service targetPorts name a port of the pods they select")

    cfg_name = "fxstreamd-cluster-config"
    cfg = json.loads(cms.get(cfg_name, {}).get("data", {}).get("fxstreamd.json", "{}"))
    single = json.loads(next(d for _, d in load_manifests() if d["kind"] == "ConfigMap")["data"]["fxstreamd.json"])
    extra = sorted(set(cfg) - set(single) - {"cluster", "node_id", "role"})
    t.check(cfg and not extra, "the cluster ConfigMap uses only keys the single-node one has (started below) or "
            "cluster/node_id/role %s" % extra)
    t.check(cfg.get("limits") == single.get("limits"), "same limits as the single-node set")
    redis_url = None
    for role, w in (("compute", comp), ("edge", edge)):
        pod = w["spec"]["template"]
        c = pod["spec"]["containers"][0]
        a = pairs(c.get("args", []))
        env = {e["name"]: e for e in c.get("env", [])}
        t.check(a.get("--role") == role and " ".join(c["args"]).count("--role") == 1, "--role %s in %s" %
                (role, w["metadata"]["name"]))
        t.check(a.get("--node-id") == "$(POD_NAME)" and
                env.get("POD_NAME", {}).get("valueFrom", {}).get("fieldRef", {}).get("fieldPath") == "metadata.name",
                "%s: --node-id is the pod name (downward API)" % role)
        u = urllib.parse.urlsplit(a.get("--cluster", ""))
        redis_url = redis_url or a.get("--cluster")
        rport = next((p["port"] for p in rsvc["spec"]["ports"] if p.get("name") == "redis"), None)
        t.check(u.scheme == "redis" and u.hostname == "fxstream-redis" and u.port == rport and
                u.username is None and u.password is None and re.fullmatch(r"/\d+", u.path or "/0"),
                "%s: --cluster %s names the Redis Service and its port, no credentials" % (role, a.get("--cluster")))
        t.check(secret_ref(env, "FXS_REDIS_PASSWORD") == ("fxstreamd-redis", "password"),
                "%s: FXS_REDIS_PASSWORD from Secret fxstreamd-redis key password" % role)
        t.check(secret_ref(env, "FXSTREAMD_TOKENS") == ("fxstreamd-tokens", "FXSTREAMD_TOKENS"),
                "%s: tokens from Secret fxstreamd-tokens" % role)
        mounts = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
        vols = {v["name"]: v for v in pod["spec"]["volumes"]}
        conf = a.get("--config", "")
        t.check(vols.get(mounts.get(os.path.dirname(conf)), {}).get("configMap", {}).get("name") == cfg_name,
                "%s: --config is the cluster ConfigMap's file" % role)
        t.check("emptyDir" in vols.get(mounts.get(cfg.get("state_dir")), {}) and "emptyDir" in vols.get(
            mounts.get("/tmp"), {}) and c["securityContext"].get("readOnlyRootFilesystem") is True,
            "%s: read-only root filesystem; state dir (presets) and /tmp on emptyDir" % role)
        probes = [c.get(p, {}).get("httpGet", {}) for p in ("livenessProbe", "readinessProbe", "startupProbe")]
        t.check(all(p.get("path") == "/healthz" and p.get("port") == "http" for p in probes) and "http" in ports[role]
                and ports[role]["http"] == cfg.get("port") and cfg.get("listen") == "0.0.0.0",
                "%s: liveness, readiness and startup probes ask /healthz on the named port the daemon listens on" % role)
        ann = pod["metadata"].get("annotations", {})
        t.check(ann.get("prometheus.io/scrape") == "true" and ann.get("prometheus.io/path") == "/metrics" and
                int(ann.get("prometheus.io/port", 0)) == cfg.get("port"), "%s: Prometheus scrape annotations" % role)
        res = c.get("resources", {})
        t.check(all(k in res.get(x, {}) for x in ("requests", "limits") for k in ("cpu", "memory")),
                "%s: resource requests and limits" % role)
    cpu = lambda w: w["spec"]["template"]["spec"]["containers"][0]["resources"]["requests"]["cpu"]  # noqa: E731
    milli = lambda q: int(q[:-1]) if str(q).endswith("m") else int(float(q) * 1000)  # noqa: E731
    t.check(milli(cpu(edge)) < milli(cpu(comp)), "edge daemons request less CPU than compute daemons")
    cenv = {e["name"]: e for e in comp["spec"]["template"]["spec"]["containers"][0]["env"]}
    cmounts = {m["mountPath"] for m in comp["spec"]["template"]["spec"]["containers"][0]["volumeMounts"]}
    t.check(cenv.get("POCL_CACHE_DIR", {}).get("value", "").startswith("/var/cache/fxstream") and
            "/var/cache/fxstream" in cmounts, "compute: PoCL's kernel cache on a writable volume")
    t.check(comp["spec"].get("replicas") == 2 and "replicas" not in edge["spec"],
            "2 compute replicas; the edge count is the autoscaler's (no replicas to reset it)")
    uid = int(re.search(r"--uid (\d+)", open(os.path.join(DEPLOY, "Dockerfile")).read()).group(1))
    scs = {n: w["spec"]["template"]["spec"].get("securityContext", {}) for n, w in
           (("compute", comp), ("edge", edge), ("redis", redis))}
    t.check(all(s.get("runAsNonRoot") is True and s.get("runAsUser") == uid and s.get("fsGroup") == uid
                for s in scs.values()), "every pod runs as the non-root uid %d" % uid)

    hpa = next(iter(by.get("HorizontalPodAutoscaler", {}).values()), {})
    ref = hpa.get("spec", {}).get("scaleTargetRef", {})
    t.check(ref == {"apiVersion": "apps/v1", "kind": "Deployment", "name": "fxstreamd-edge"},
            "the HPA scales the edge Deployment")
    mets = hpa.get("spec", {}).get("metrics", [])
    pm = [m["pods"] for m in mets if m.get("type") == "Pods"]
    t.check(pm and pm[0]["metric"]["name"] == "fxs_connections" and pm[0]["target"]["type"] == "AverageValue" and
            int(pm[0]["target"]["averageValue"]) > 0, "HPA: Pods metric fxs_connections, an average value per pod")
    t.check(any(m.get("type") == "Resource" and m["resource"]["name"] == "cpu" for m in mets),
            "HPA: a CPU fallback metric")
    t.check(hpa["spec"].get("minReplicas", 1) >= 2 and hpa["spec"]["maxReplicas"] > hpa["spec"]["minReplicas"],
            "HPA: at least 2 edge pods")

    ing = next(iter(by.get("Ingress", {}).values()), {})
    backends = [p["backend"]["service"] for r in ing["spec"]["rules"] for p in r["http"]["paths"]]
    t.check(backends and all(b["name"] == "fxstreamd" and b["port"].get("name") in
                             [p["name"] for p in client["spec"]["ports"]] for b in backends) and
            not any("hash" in k for k in ing["metadata"].get("annotations", {})),
            "Ingress: to Service fxstreamd by port name, no hashing")

    # Redis: image, persistence, password, probes; then its command, run for real.
    rpod = redis["spec"]["template"]["spec"]
    rc = rpod["containers"][0]
    renv = {e["name"]: e for e in rc.get("env", [])}
    t.check(rc["image"] == "redis:7.0", "Redis image redis:7.0")
    t.check(secret_ref(renv, "REDIS_PASSWORD") == secret_ref(renv, "REDISCLI_AUTH") == ("fxstreamd-redis", "password"),
            "Redis's requirepass and its probes' password: Secret fxstreamd-redis key password, as the daemons'")
    rconf_cm = cms.get("fxstream-redis-config", {}).get("data", {}).get("redis.conf", "")
    directives = {}
    for line in rconf_cm.splitlines():
        w = line.split(None, 1)
        if w and not w[0].startswith("#"):
            directives[w[0]] = w[1].strip() if len(w) > 1 else ""
    t.check(directives.get("appendonly") == "yes" and directives.get("appendfsync") == "always",
            "redis.conf: appendonly yes, appendfsync always")
    rmounts = {m["mountPath"]: m["name"] for m in rc["volumeMounts"]}
    rvols = {v["name"]: v for v in rpod["volumes"]}
    claims = {v["metadata"]["name"] for v in redis["spec"].get("volumeClaimTemplates", [])}
    t.check(rmounts.get(directives.get("dir")) in claims, "Redis's dir is on its PersistentVolumeClaim")
    script = rc["args"][0] if rc.get("command") == ["sh", "-c"] and len(rc.get("args", [])) == 1 else ""
    conf_arg = re.search(r"redis-server (\S+)", script)
    auth = directives.get("include", "")
    t.check(conf_arg and rvols.get(rmounts.get(os.path.dirname(conf_arg.group(1))), {}).get("configMap", {}).get(
        "name") == "fxstream-redis-config", "redis-server reads the ConfigMap's redis.conf")
    t.check(auth and auth in script and rvols.get(rmounts.get(os.path.dirname(auth)), {}).get("emptyDir", {}).get(
        "medium") == "Memory", "the password file redis.conf includes is written at start, on a memory emptyDir")
    t.check(rc["securityContext"].get("readOnlyRootFilesystem") is True, "Redis: read-only root filesystem")
    rprobes = [rc.get(p, {}).get("exec", {}).get("command", []) for p in ("livenessProbe", "readinessProbe",
                                                                          "startupProbe")]
    t.check(all(p and "redis-cli ping" in p[-1] and "PONG" in p[-1] for p in rprobes),
            "Redis probes: redis-cli ping must answer PONG (redis-cli exits 0 on NOAUTH too)")
    run_redis(t, script, rconf_cm, conf_arg.group(1) if conf_arg else "", auth, directives.get("dir", ""), rprobes[0])


def run_redis(t, script, conf, conf_path, auth_path, data_dir, probe):
    """The container's command with this machine's redis-server, paths moved into a temp dir."""
    server = shutil.which("redis-server")
    cli = shutil.which("redis-cli")
    if not t.check(server and cli and script and probe, "redis-server and redis-cli installed (install-deps.sh)"):
        return
    tmp = tempfile.mkdtemp(prefix="fxs-redis-")
    proc = None
    try:
        s = socket.socket()
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        s.close()
        d = {p: os.path.join(tmp, p.strip("/").replace("/", "_")) for p in
             (os.path.dirname(conf_path), os.path.dirname(auth_path), data_dir)}
        for x in d.values():
            os.makedirs(x, exist_ok=True)
        moved = lambda text: re.sub("|".join(re.escape(p) for p in sorted(d, key=len, reverse=True)),  # noqa: E731
                                    lambda m: d[m.group(0)], text)
        conf = moved(conf)
        conf = re.sub(r"^port \d+", "port %d" % port, conf, flags=re.M)
        conf = re.sub(r"^bind .*", "bind 127.0.0.1", conf, flags=re.M)  # loopback only for the test
        with open(moved(conf_path), "w") as f:
            f.write(conf)
        body = moved(script)
        env = {k: v for k, v in os.environ.items() if not k.startswith("REDIS")}
        r = subprocess.run(["sh", "-c", body], env=dict(env, REDIS_PASSWORD=""), capture_output=True, text=True,
                           timeout=20)
        t.check(r.returncode != 0 and "empty password" in r.stderr, "the Redis command refuses an empty password")
        pw = "deploy-test-redis-0123456789abcdef"
        proc = subprocess.Popen(["sh", "-c", body], env=dict(env, REDIS_PASSWORD=pw), stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
        cmd = lambda *a, auth=pw: subprocess.run([cli, "-p", str(port), *a], capture_output=True, text=True,  # noqa
                                                 timeout=10, env=dict(env, REDISCLI_AUTH=auth) if auth else env)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and "PONG" not in cmd("ping").stdout and proc.poll() is None:
            time.sleep(0.1)
        t.check("PONG" in cmd("ping").stdout, "Redis starts with the manifest's command and redis.conf")
        t.check("NOAUTH" in cmd("ping", auth=None).stdout + cmd("ping", auth=None).stderr,
                "Redis refuses clients without the password")
        t.check(cmd("config", "get", "appendonly").stdout.split() == ["appendonly", "yes"] and
                cmd("config", "get", "appendfsync").stdout.split() == ["appendfsync", "always"] and
                cmd("config", "get", "maxmemory-policy").stdout.split() == ["maxmemory-policy", "noeviction"],
                "the running Redis has appendonly yes, appendfsync always, noeviction")
        cmd("set", "fxs:deploy-test", "1")
        aof = os.path.join(d[data_dir], "appendonlydir")
        t.check(os.path.isdir(aof) and any(".incr.aof" in f for f in os.listdir(aof)),
                "the AOF is written in Redis's dir (the PVC)")
        st = os.stat(moved(auth_path))
        t.check(st.st_mode & 0o077 == 0, "the password file is readable by its owner only")
        probe_sh = probe[-1].replace("redis-cli", "%s -p %d" % (cli, port))
        ok = subprocess.run([*probe[:-1], probe_sh], env=dict(env, REDISCLI_AUTH=pw), timeout=10).returncode
        bad = subprocess.run([*probe[:-1], probe_sh], env=dict(env, REDISCLI_AUTH="wrong-password"),
                             timeout=10, capture_output=True).returncode
        t.check(ok == 0 and bad != 0, "the probe command passes with the password and fails without it")
    finally:
        if proc:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=10)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()
        shutil.rmtree(tmp, ignore_errors=True)


def test_cluster_dropin(t):
    """deploy/fxstreamd-cluster.conf, a drop-in for the unit: verified merged with it."""
    if not t.check(os.path.exists(DROPIN), "deploy/fxstreamd-cluster.conf exists"):
        return
    unit, drop = open(UNIT).read(), open(DROPIN).read()
    d = unit_directives(drop)
    starts = d.get("ExecStart", [])
    t.check(len(starts) == 2 and starts[0] == "", "the drop-in resets ExecStart= before setting its own")
    exec_start = starts[-1] if starts else ""
    a = pairs(exec_start.split())
    base = unit_directives(unit)["ExecStart"][0]
    t.check(exec_start.startswith(base + " "), "its ExecStart is the unit's plus cluster flags")
    u = urllib.parse.urlsplit(a.get("--cluster", ""))
    t.check(u.scheme == "redis" and u.hostname and u.password is None and u.username is None and
            a.get("--role") in ("compute", "edge", "both") and "--node-id" in a,
            "--cluster redis://HOST (no credentials), --role and --node-id")
    t.check(any("FXS_REDIS_PASSWORD" in ln for ln in drop.splitlines() if ln.startswith("#")) and
            any(f.lstrip("-").endswith(".env") for f in d.get("EnvironmentFile", [])) and
            "FXS_REDIS_PASSWORD=" not in "".join(d.get("Environment", [])),
            "the password comes from an EnvironmentFile, not from the drop-in")
    merged = (unit + "\n" + drop).replace(base.split()[0], DAEMON)
    rc, out = verify_unit(merged)
    t.check(rc == 0 and out == "", "systemd-analyze verify: unit + drop-in, no complaint" +
            ("" if not out else ": " + out[-400:]))
    rc, out = verify_unit(merged.replace("\nExecStart=\n", "\n", 1))
    t.check(rc != 0 or "ExecStart" in out, "and a drop-in without the ExecStart= reset is refused")


def test_nginx_cluster(t):
    """deploy/nginx/fxstream-cluster.conf: round robin, run in front of two daemons."""
    if not t.check(os.path.exists(NGINX_CLUSTER), "deploy/nginx/fxstream-cluster.conf exists"):
        return
    text = open(NGINX_CLUSTER).read()
    t.check(not re.search(r"^\s*(hash|ip_hash|least_conn|random)\b", text, re.M),
            "fxstream-cluster.conf: plain round robin (no hash)")
    t.check(re.search(r"proxy_set_header Upgrade \$http_upgrade;", text) and re.search(r"proxy_http_version 1\.1;", text)
            and re.search(r"proxy_read_timeout\s+1h;", text), "it passes the WebSocket upgrade, 1 h read timeout")
    t.check(re.search(r"^\s*hash \$arg_stream consistent;", open(os.path.join(DEPLOY, "nginx", "fxstream.conf")).read(),
                      re.M), "the single-node file keeps its consistent hash")
    import asyncio
    import test_scaleout as so
    so.CONF = NGINX_CLUSTER
    daemons, proxy = [], None
    try:
        for _ in range(2):
            proc, port = start_daemon([])
            daemons.append((proc, port))
        if not t.check(all(p for _, p in daemons), "two daemons start"):
            return
        proxy = so.Proxy([p for _, p in daemons])
        r = proxy.test_config()
        t.check(r.returncode == 0, "nginx -t accepts fxstream-cluster.conf" +
                ("" if not r.returncode else ": " + r.stderr[-300:]))
        proxy.start()

        def gauge(port):
            body = urllib.request.urlopen("http://127.0.0.1:%d/metrics" % port, timeout=10).read().decode()
            typ = re.search(r"^# TYPE fxs_connections (\w+)$", body, re.M)
            val = re.search(r"^fxs_connections (\d+)$", body, re.M)
            return (typ.group(1) if typ else None), (int(val.group(1)) if val else None)

        async def spread():
            import websockets
            conns = [await asyncio.wait_for(websockets.connect(
                "ws://127.0.0.1:%d/v1/ws?stream=flame" % proxy.port, subprotocols=["fxstream.v1"],
                ping_interval=None), 10) for _ in range(4)]
            try:
                for c in conns:
                    await asyncio.wait_for(c.recv(), 10)  # the hello: the daemon has the session
                return [gauge(p) for _, p in daemons]
            finally:
                for c in conns:
                    await c.close()
        g = asyncio.run(spread())
        t.check(all(typ == "gauge" for typ, _ in g), "fxs_connections (what the edge HPA reads) is a gauge")
        t.check([v for _, v in g] == [2, 2], "4 WebSockets naming one stream: 2 on each daemon %s" % g)
    except Exception as e:
        t.check(False, "nginx in front of two daemons: %s: %s" % (type(e).__name__, e))
    finally:
        if proxy:
            proxy.stop()
        for proc, _ in daemons:
            stop(proc)


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
    for test in (test_unit, test_unit_filters, test_cluster_dropin, test_k8s_schema, test_k8s_wiring,
                 test_k8s_cluster_schema, test_k8s_cluster_wiring, test_nginx_cluster, test_dockerfile):
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
