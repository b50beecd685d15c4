"""Checks the Kubernetes recipe (cluster/kubernetes/pytorchjob.yaml) without a cluster: it parses
as YAML, is a Kubeflow PyTorchJob (kubeflow.org/v1) whose replicas run a container named
`pytorch` (the operator's requirement) with GPUs as many as nprocPerNode, its inline bash script
parses (`bash -n`), and every `torchrun -m scaledp_data.train ...` command line in it is accepted
by the trainer's own argument parser.

    python check_k8s_recipe.py MANIFEST

Prints one JSON line: {"errors": [...], "commands": [[args...], ...]}.
"""

import argparse
import json
import shlex
import subprocess
import sys

import yaml

from scaledp_data.policy.options import add_arguments


def commands(script):
    """The argument lists of the script's `torchrun -m scaledp_data.train` commands."""
    out = []
    for line in script.replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        if "torchrun" in words and "scaledp_data.train" in words:
            rest = words[words.index("scaledp_data.train") + 1:]
            out.append([w.replace('"', "") for w in rest])
    return out


def main():
    """Checks the manifest and prints the report."""
    errors = []
    with open(sys.argv[1]) as f:
        doc = yaml.safe_load(f)
    if doc.get("apiVersion") != "kubeflow.org/v1" or doc.get("kind") != "PyTorchJob":
        errors.append(f"not a kubeflow.org/v1 PyTorchJob: {doc.get('apiVersion')} {doc.get('kind')}")
    spec = doc.get("spec", {})
    nproc = int(spec.get("nprocPerNode", 0))
    replicas = spec.get("pytorchReplicaSpecs", {})
    if set(replicas) != {"Master", "Worker"} or replicas["Master"].get("replicas") != 1:
        errors.append(f"replica specs {sorted(replicas)}: one Master and Workers expected")
    found = []
    for role, r in replicas.items():
        containers = r["template"]["spec"]["containers"]
        c = next((c for c in containers if c.get("name") == "pytorch"), None)
        if c is None:
            errors.append(f"{role}: no container named pytorch")
            continue
        gpus = int(c.get("resources", {}).get("limits", {}).get("nvidia.com/gpu", 0))
        if gpus != nproc:
            errors.append(f"{role}: {gpus} GPUs for nprocPerNode {nproc}")
        script = c["args"][0] if c.get("command", [])[:2] == ["bash", "-c"] else " ".join(c["command"])
        check = subprocess.run(["bash", "-n"], input=script, text=True, capture_output=True)
        if check.returncode != 0:
            errors.append(f"{role}: bash -n: {check.stderr.strip()}")
        for args in commands(script):
            p = argparse.ArgumentParser(exit_on_error=False)
            add_arguments(p)
            try:
                a, unknown = p.parse_known_args(args)
                if unknown:
                    errors.append(f"{role}: the trainer takes no {unknown}")
            except (argparse.ArgumentError, SystemExit) as e:
                errors.append(f"{role}: {args}: {e}")
            found.append(args)
    if not found:
        errors.append("no torchrun -m scaledp_data.train command")
    print(json.dumps({"errors": errors, "commands": found}))


if __name__ == "__main__":
    main()
