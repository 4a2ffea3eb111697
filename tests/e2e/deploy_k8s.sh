#!/bin/sh
# tests/e2e/deploy_k8s.sh: deploy/k8s/terrafarm.yaml.  Parsed with python3's yaml module
# (skipped, with the reason, when it is missing) and checked for the wiring that makes it run:
# the Service selects the coordinator pods and targets its named port; the coordinator listens
# on all addresses at that port with the secret; the worker Job runs N > 1 pods connecting to
# the Service at that port with the same Secret; every volume mounted is declared; every
# Secret volume names terrafarm-secret.  The scene in the ConfigMap is parsed by terrafarm
# itself (a tiny render), so the example cannot rot.
set -u
ROOT=${TF_ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
TF=${TF_BIN:-$ROOT/bin/terrafarm}
K=$ROOT/deploy/k8s/terrafarm.yaml
fail() { echo "FAIL: $*"; exit 1; }
[ -r "$K" ] || fail "$K is missing"
grep -q '^# .*kubectl apply -f deploy/k8s/terrafarm.yaml' "$K" || fail "no usage in the header"
command -v python3 >/dev/null 2>&1 || { echo "skipped: python3 is not installed"; exit 77; }
python3 -c 'import yaml' 2>/dev/null || { echo "skipped: python3 has no yaml module"; exit 77; }
T=$(mktemp -d "${TMPDIR:-/tmp}/tf-deploy-k8s.XXXXXX") || fail "mktemp"
trap 'rm -rf "$T"' EXIT

python3 - "$K" "$T/render.scene" <<'PY' || fail "manifest check failed"
import sys, yaml

def check(cond, what):
    if not cond:
        print("FAIL: " + what)
        sys.exit(1)

docs = [d for d in yaml.safe_load_all(open(sys.argv[1])) if d]
by = {(d["kind"], d["metadata"]["name"]): d for d in docs}
for key in [("ConfigMap", "terrafarm-scene"), ("Service", "terrafarm-coordinator"),
            ("Job", "terrafarm-coordinator"), ("Job", "terrafarm-workers"),
            ("PersistentVolumeClaim", "terrafarm-output")]:
    check(key in by, "missing %s %s" % key)

svc = by[("Service", "terrafarm-coordinator")]
coord = by[("Job", "terrafarm-coordinator")]["spec"]["template"]
workers_job = by[("Job", "terrafarm-workers")]["spec"]
workers = workers_job["template"]

labels = coord["metadata"]["labels"]
for k, v in svc["spec"]["selector"].items():
    check(labels.get(k) == v, "Service selector %s=%s does not match the coordinator pod" % (k, v))
for k, v in svc["spec"]["selector"].items():
    if workers["metadata"]["labels"].get(k) != v:
        break
else:
    check(False, "Service selector also matches the worker pods")
port = svc["spec"]["ports"][0]
c = coord["spec"]["containers"][0]
named = {p["name"]: p["containerPort"] for p in c.get("ports", [])}
check(port["targetPort"] in named, "Service targetPort %r is not a coordinator port" % port["targetPort"])
check(named[port["targetPort"]] == port["port"], "Service port and container port differ")

def arg_after(args, flag):
    check(flag in args, "%s missing from %s" % (flag, args))
    return str(args[args.index(flag) + 1])

cargs = [str(a) for a in c["args"]]
check(cargs[0] == "render", "the coordinator does not run `terrafarm render`")
check("--resume" in cargs, "the coordinator Job must pass --resume: a restarted pod would "
      "otherwise refuse its own partial image")
check(arg_after(cargs, "--listen") == "0.0.0.0:%d" % port["port"], "coordinator --listen")
w = workers["spec"]["containers"][0]
wargs = [str(a) for a in w["args"]]
check(wargs[0] == "worker", "the workers do not run `terrafarm worker`")
check(arg_after(wargs, "--connect") == "%s:%d" % (svc["metadata"]["name"], port["port"]),
      "workers do not connect to the Service")
check(workers_job["parallelism"] > 1, "worker Job parallelism must be > 1 (N workers)")
check(workers_job["completions"] == workers_job["parallelism"], "completions != parallelism")
check(int(arg_after(cargs, "--wait-workers")) ==
      int(arg_after(cargs, "-j")) + workers_job["parallelism"] * int(arg_after(wargs, "-j")),
      "coordinator --wait-workers is not its own -j plus parallelism x the workers' -j")
check(coord["spec"]["restartPolicy"] in ("OnFailure", "Never"), "Job restartPolicy")

for pod, ctr, args in ((coord, c, cargs), (workers, w, wargs)):
    vols = {v["name"]: v for v in pod["spec"]["volumes"]}
    mounts = {m["mountPath"]: m["name"] for m in ctr["volumeMounts"]}
    for name in mounts.values():
        check(name in vols, "volume %s mounted but not declared" % name)
    secret = arg_after(args, "--secret-file")
    d = secret.rsplit("/", 1)[0]
    check(d in mounts, "--secret-file %s is not on a mounted volume" % secret)
    vol = vols[mounts[d]]
    check(vol.get("secret", {}).get("secretName") == "terrafarm-secret",
          "--secret-file is not from the terrafarm-secret Secret")
    check(pod["spec"]["securityContext"].get("runAsNonRoot") is True, "pods must not run as root")

scene = cargs[1]  # render SCENE ...
cvols = {v["name"]: v for v in coord["spec"]["volumes"]}
cm = {m["mountPath"]: m["name"] for m in c["volumeMounts"]}
d, f = scene.rsplit("/", 1)
check(cvols[cm[d]]["configMap"]["name"] == "terrafarm-scene", "scene is not from the ConfigMap")
open(sys.argv[2], "w").write(by[("ConfigMap", "terrafarm-scene")]["data"][f])
print("deploy_k8s: %d documents; %d worker pods -> %s:%d" % (len(docs), workers_job["parallelism"],
      svc["metadata"]["name"], port["port"]))
PY
"$TF" render "$T/render.scene" --size 32x18 -j 1 -q -o "$T/k8s.exr" ||
    fail "the ConfigMap's scene does not render"
echo "deploy_k8s: ok"
