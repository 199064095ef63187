#!/usr/bin/env python3
"""Checks the fields that tie deploy/k8s's bake Jobs to vistream-pvs's command line.

yamllint checks the files' form; this checks what Kubernetes and the tool
must agree on, where a slip would bake the wrong shards silently. The same
checks run for each bake and its merge (the PVS pair and the impostor pair):
  - the bake Job is Indexed, runs its vistream-pvs subcommand with
    --shard "${JOB_COMPLETION_INDEX}/${SHARDS}", and its completions equal
    SHARDS (a shard no pod bakes is a hole; a pod beyond SHARDS is refused by
    the tool), parallelism at most completions;
  - every bake pod writes a distinct file under the shared volume's mount,
    named with its index, and the merge Job reads exactly that pattern with
    the same SHARDS and writes outside the shards' folder, on the volume;
  - no merge's pattern takes another pair's shards too.
Between the pairs: the impostor bake reads (--db) the database the PVS merge
writes, for the same SCENE. All Jobs mount the claim of bake-volume.yaml
(ReadWriteMany) at the same path and run the same image, as a non-root user.

Usage: check_k8s.py [--dir DIR] (default: deploy/k8s beside this script's
repository). Prints one line per problem and exits 1 if there is any.
"""

import argparse
import fnmatch
import os
import re
import sys
from collections import namedtuple

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from planted_slips import Problems  # noqa: E402

# A bake and its merge: the manifests and the vistream-pvs subcommands they run.
Pair = namedtuple("Pair", "name bake_file merge_file bake_command merge_command")
PVS = Pair("pvs", "pvs-bake-job.yaml", "pvs-merge-job.yaml", "bake", "merge")
IMPOSTORS = Pair("impostor", "impostor-bake-job.yaml", "impostor-merge-job.yaml",
                 "impostors", "impostor-merge")
PAIRS = (PVS, IMPOSTORS)


def load(path):
    with open(path, encoding="utf-8") as f:
        return yaml.safe_load(f)


def env_of(container):
    return {e["name"]: str(e.get("value", "")) for e in container.get("env", [])}


def command_of(container):
    return " ".join(container.get("command", []) + container.get("args", []))


def option(command, *names):
    """The value of the first of `names` (e.g. --out, -o) in `command`, or None."""
    flags = "|".join(re.escape(n) for n in names)
    m = re.search(rf'(?<![\w-])(?:{flags})[ =]"?([^" ]+)"?', command)
    return m.group(1) if m else None


def check(directory):
    problems = Problems()
    need = problems.need

    try:
        volume = load(os.path.join(directory, "bake-volume.yaml"))
        jobs = {f: load(os.path.join(directory, f))
                for p in PAIRS for f in (p.bake_file, p.merge_file)}
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

    def mount_and_claim(name, spec, container):
        mounts = {m["name"]: m["mountPath"] for m in container.get("volumeMounts", [])}
        claims = {v["name"]: v.get("persistentVolumeClaim", {}).get("claimName")
                  for v in spec.get("volumes", [])}
        used = [n for n in mounts if claims.get(n) == claim]
        need(len(used) == 1, f"{name}: mounts no volume of claim {claim!r}")
        need(spec.get("securityContext", {}).get("runAsNonRoot") is True,
             f"{name}: pods must run as a non-root user")
        return mounts[used[0]] if used else None

    # Every Job: a batch/v1 Job, one container, the claim at one path, one image.
    containers, mounts = {}, {}
    for name, job in jobs.items():
        need(job.get("kind") == "Job" and job.get("apiVersion") == "batch/v1",
             f"{name}: not a batch/v1 Job")
        spec, containers[name] = pod(job, name)
        mounts[name] = mount_and_claim(name, spec, containers[name])
    first = PVS.bake_file
    for name in jobs:
        need(mounts[name] == mounts[first],
             f"the Jobs mount the volume at different paths: {name} {mounts[name]}, "
             f"{first} {mounts[first]}")
        need(containers[name].get("image") == containers[first].get("image"),
             f"the Jobs run different images: {name} {containers[name].get('image')!r}, "
             f"{first} {containers[first].get('image')!r}")

    def on_volume(path, mount):
        return mount is not None and path.startswith(mount.rstrip("/") + "/")

    def check_pair(pair):
        """The bake and merge of `pair`; returns (shard pattern, merged file), None if unknown."""
        bake, merge = pair.bake_file, pair.merge_file
        bake_container, merge_container = containers[bake], containers[merge]
        mount = mounts[bake]
        # The bake: Indexed, shards from the completion index, one file each.
        spec = jobs[bake].get("spec", {})
        need(spec.get("completionMode") == "Indexed",
             f"{bake}: completionMode must be Indexed (JOB_COMPLETION_INDEX)")
        shards = env_of(bake_container).get("SHARDS", "")
        if need(shards.isdigit() and int(shards) > 0, f"{bake}: SHARDS must be a positive integer"):
            need(spec.get("completions") == int(shards),
                 f"{bake}: completions {spec.get('completions')} != SHARDS {shards}")
            need(0 < spec.get("parallelism", 1) <= int(shards),
                 f"{bake}: parallelism must lie in 1..completions")
        bake_command = command_of(bake_container)
        need(re.search(rf"\bvistream-pvs {re.escape(pair.bake_command)}(?![\w-])", bake_command)
             is not None, f"{bake}: does not run vistream-pvs {pair.bake_command}")
        need(re.search(r'--shard "?\$\{JOB_COMPLETION_INDEX\}/\$\{SHARDS\}"?', bake_command)
             is not None, f"{bake}: --shard must be ${{JOB_COMPLETION_INDEX}}/${{SHARDS}}")
        path = option(bake_command, "--out", "-o")
        if not need(path is not None, f"{bake}: no --out"):
            return None, None
        need(on_volume(path, mount), f"{bake}: --out {path} is not on the shared volume ({mount})")
        need("${JOB_COMPLETION_INDEX}" in path, f"{bake}: --out {path} is the same file for every pod")
        # The merge reads the bake's pattern, with its SHARDS, and writes elsewhere.
        merge_command = command_of(merge_container)
        pattern = path.replace("${JOB_COMPLETION_INDEX}", "*")
        run = re.search(rf"\bvistream-pvs {re.escape(pair.merge_command)}(?![\w-])(.*)",
                        merge_command)
        if not need(run is not None, f"{merge}: does not run vistream-pvs {pair.merge_command}"):
            return pattern, None
        need(pattern in merge_command, f"{merge}: does not read the bake's shards {pattern}")
        need('"$@"' in run.group(1), f'{merge}: does not pass the shards it found ("$@")')
        need(env_of(merge_container).get("SHARDS") == shards,
             f"{merge}: SHARDS {env_of(merge_container).get('SHARDS')} != the bake's {shards}")
        merged = option(run.group(1), "--out", "-o")
        if not need(merged is not None, f"{merge}: no --out for the merged database"):
            return pattern, None
        need(os.path.dirname(merged) != os.path.dirname(path),
             f"{merge}: the merged database lands among the shards")
        need(on_volume(merged, mounts[merge]),
             f"{merge}: the merged database {merged} is not on the shared volume")
        return pattern, merged

    results = {pair.name: check_pair(pair) for pair in PAIRS}

    # A merge must not take another pair's shards: with SHARDS and the index
    # filled in, no pattern may match another pair's pattern.
    for pair in PAIRS:
        mine = results[pair.name][0]
        for other in PAIRS:
            theirs = results[other.name][0]
            if other is pair or mine is None or theirs is None:
                continue
            need(not fnmatch.fnmatch(theirs.replace("*", "0"), mine),
                 f"{pair.merge_file}: its pattern {mine} also takes {other.name} shards {theirs}")

    # The impostor bake reads the PVS merge's database, of the same scene.
    pvs_merged = results[PVS.name][1]
    impostor_command = command_of(containers[IMPOSTORS.bake_file])
    db = option(impostor_command, "--db")
    if need(db is not None, f"{IMPOSTORS.bake_file}: no --db (the merged PVS database)"):
        need(pvs_merged is None or db == pvs_merged,
             f"{IMPOSTORS.bake_file}: --db {db} is not the PVS merge's output {pvs_merged}")
    scenes = [env_of(containers[p.bake_file]).get("SCENE") for p in (PVS, IMPOSTORS)]
    need(scenes[0] == scenes[1],
         f"{IMPOSTORS.bake_file}: SCENE {scenes[1]} != the PVS bake's {scenes[0]}")
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
