#!/usr/bin/env python3
"""Checks the fields that tie deploy/k8s's bake Jobs to vistream-pvs's command line.

yamllint checks the files' form; this checks what Kubernetes and the tool
must agree on, where a slip would bake the wrong shards silently:
  - the bake Job is Indexed, runs `vistream-pvs bake` with
    --shard "${JOB_COMPLETION_INDEX}/${SHARDS}", and its completions equal
    SHARDS (a shard no pod bakes is a hole; a pod beyond SHARDS is refused by
    the tool), parallelism at most completions;
  - every bake pod writes a distinct file under the shared volume's mount,
    named with its index, and the merge Job reads exactly that pattern with
    the same SHARDS and writes outside the shards' folder;
  - both Jobs mount the claim of bake-volume.yaml (ReadWriteMany) at the
    same path and run the same image, as a non-root user.

Usage: check_k8s.py [--dir DIR] (default: deploy/k8s beside this script's
repository). Prints one line per problem and exits 1 if there is any.
"""

import argparse
import os
import re
import sys

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from planted_slips import Problems  # noqa: E402


def load(path):
    with open(path, encoding="utf-8") as f:
        return yaml.safe_load(f)


def env_of(container):
    return {e["name"]: str(e.get("value", "")) for e in container.get("env", [])}


def command_of(container):
    return " ".join(container.get("command", []) + container.get("args", []))


def check(directory):
    problems = Problems()
    need = problems.need

    try:
        volume = load(os.path.join(directory, "bake-volume.yaml"))
        bake = load(os.path.join(directory, "pvs-bake-job.yaml"))
        merge = load(os.path.join(directory, "pvs-merge-job.yaml"))
    except (OSError, yaml.YAMLError) as e:
        return [f"cannot read the manifests: {e}"]

    need(volume.get("kind") == "PersistentVolumeClaim", "bake-volume.yaml: not a PersistentVolumeClaim")
    claim = volume.get("metadata", {}).get("name")
    need("ReadWriteMany" in volume.get("spec", {}).get("accessModes", []),
         "bake-volume.yaml: pods on several nodes need ReadWriteMany")

    def pod(job, name):
        spec = job.get("spec", {}).get("template", {}).get("spec", {})
        containers = spec.get("containers", [])
        if not need(len(containers) == 1, f"{name}: expected one container"):
            return spec, {}
        return spec, containers[0]

    def mount_and_claim(job, name, spec, container):
        mounts = {m["name"]: m["mountPath"] for m in container.get("volumeMounts", [])}
        claims = {v["name"]: v.get("persistentVolumeClaim", {}).get("claimName")
                  for v in spec.get("volumes", [])}
        used = [n for n in mounts if claims.get(n) == claim]
        need(len(used) == 1, f"{name}: mounts no volume of claim {claim!r}")
        need(spec.get("securityContext", {}).get("runAsNonRoot") is True,
             f"{name}: pods must run as a non-root user")
        return mounts[used[0]] if used else None

    for job, name in ((bake, "pvs-bake-job.yaml"), (merge, "pvs-merge-job.yaml")):
        need(job.get("kind") == "Job" and job.get("apiVersion") == "batch/v1",
             f"{name}: not a batch/v1 Job")

    bake_spec, bake_container = pod(bake, "pvs-bake-job.yaml")
    merge_spec, merge_container = pod(merge, "pvs-merge-job.yaml")
    bake_mount = mount_and_claim(bake, "pvs-bake-job.yaml", bake_spec, bake_container)
    merge_mount = mount_and_claim(merge, "pvs-merge-job.yaml", merge_spec, merge_container)
    need(bake_mount == merge_mount, f"the Jobs mount the volume at {bake_mount} and {merge_mount}")
    need(bake_container.get("image") == merge_container.get("image"),
         "the Jobs run different images")

    # The bake: Indexed, shards from the completion index, one file each.
    spec = bake.get("spec", {})
    need(spec.get("completionMode") == "Indexed",
         "pvs-bake-job.yaml: completionMode must be Indexed (JOB_COMPLETION_INDEX)")
    shards = env_of(bake_container).get("SHARDS", "")
    if need(shards.isdigit() and int(shards) > 0, "pvs-bake-job.yaml: SHARDS must be a positive integer"):
        need(spec.get("completions") == int(shards),
             f"pvs-bake-job.yaml: completions {spec.get('completions')} != SHARDS {shards}")
        need(0 < spec.get("parallelism", 1) <= int(shards),
             "pvs-bake-job.yaml: parallelism must lie in 1..completions")
    bake_command = command_of(bake_container)
    need(re.search(r"\bvistream-pvs bake\b", bake_command) is not None,
         "pvs-bake-job.yaml: does not run vistream-pvs bake")
    need(re.search(r'--shard "?\$\{JOB_COMPLETION_INDEX\}/\$\{SHARDS\}"?', bake_command) is not None,
         "pvs-bake-job.yaml: --shard must be ${JOB_COMPLETION_INDEX}/${SHARDS}")
    out = re.search(r'--out "?([^" ]+)"?', bake_command)
    if need(out is not None, "pvs-bake-job.yaml: no --out"):
        path = out.group(1)
        need(bake_mount is not None and path.startswith(bake_mount.rstrip("/") + "/"),
             f"pvs-bake-job.yaml: --out {path} is not on the shared volume ({bake_mount})")
        need("${JOB_COMPLETION_INDEX}" in path,
             f"pvs-bake-job.yaml: --out {path} is the same file for every pod")
        # The merge reads the bake's pattern, with its SHARDS.
        merge_command = command_of(merge_container)
        pattern = path.replace("${JOB_COMPLETION_INDEX}", "*")
        need(re.search(r"\bvistream-pvs merge\b", merge_command) is not None,
             "pvs-merge-job.yaml: does not run vistream-pvs merge")
        need(pattern in merge_command,
             f"pvs-merge-job.yaml: does not read the bake's shards {pattern}")
        need(env_of(merge_container).get("SHARDS") == shards,
             f"pvs-merge-job.yaml: SHARDS {env_of(merge_container).get('SHARDS')} != the bake's {shards}")
        merged = re.search(r'merge "\$@" --out "?([^" ]+)"?', merge_command)
        if need(merged is not None, "pvs-merge-job.yaml: no --out after the shards"):
            need(os.path.dirname(merged.group(1)) != os.path.dirname(path),
                 "pvs-merge-job.yaml: the merged database lands among the shards")
    return problems


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", default=os.path.join(here, "..", "..", "deploy", "k8s"))
    args = parser.parse_args()
    problems = check(args.dir)
    for p in problems:
        print(f"check_k8s: {p}")
    if not problems:
        print(f"check_k8s: the bake Jobs agree with vistream-pvs ({os.path.normpath(args.dir)})")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
