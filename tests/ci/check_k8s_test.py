#!/usr/bin/env python3
"""Plants one slip at a time in copies of deploy/k8s and expects check_k8s.py
to name it; the manifests as they are must pass."""

import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
import check_k8s  # noqa: E402
import planted_slips  # noqa: E402

SOURCE = os.path.join(here, "..", "..", "deploy", "k8s")

# (file, text replaced, replacement, words the problem must contain)
SLIPS = [
    ("pvs-bake-job.yaml", "completions: 4", "completions: 3", "completions 3 != SHARDS 4"),
    ("pvs-bake-job.yaml", "completionMode: Indexed", "completionMode: NonIndexed", "Indexed"),
    ("pvs-bake-job.yaml", '--shard "${JOB_COMPLETION_INDEX}/${SHARDS}"', '--shard "0/${SHARDS}"',
     "--shard"),
    ("pvs-bake-job.yaml", "pvs-${JOB_COMPLETION_INDEX}-of-${SHARDS}.db", "pvs.db",
     "same file for every pod"),
    ("pvs-bake-job.yaml", "mountPath: /data", "mountPath: /scratch", "not on the shared volume"),
    ("pvs-merge-job.yaml", 'value: "4"', 'value: "5"', "SHARDS 5 != the bake's 4"),
    ("pvs-merge-job.yaml", "/data/shards/pvs-*-of-", "/data/shards/shard-*-of-",
     "does not read the bake's shards"),
    ("pvs-merge-job.yaml", "claimName: vistream-bake", "claimName: other", "mounts no volume"),
    ("pvs-merge-job.yaml", "--out /data/pvs.db", "--out /data/shards/pvs.db", "among the shards"),
    ("bake-volume.yaml", "- ReadWriteMany", "- ReadWriteOnce", "ReadWriteMany"),
    ("pvs-bake-job.yaml", "runAsNonRoot: true", "runAsNonRoot: false", "non-root"),
    # The impostor pair runs the same checks, and reads the PVS merge's output.
    ("impostor-bake-job.yaml", "completions: 4", "completions: 2", "completions 2 != SHARDS 4"),
    ("impostor-bake-job.yaml", '--shard "${JOB_COMPLETION_INDEX}/${SHARDS}"',
     '--shard "1/${SHARDS}"', "--shard"),
    ("impostor-bake-job.yaml", "exec vistream-pvs impostors", "exec vistream-pvs bake",
     "does not run vistream-pvs impostors"),
    ("impostor-bake-job.yaml", "--db /data/pvs.db", "--db /data/shards/pvs-0-of-4.db",
     "not the PVS merge's output"),
    ("impostor-bake-job.yaml", "value: bigcity", "value: city1", "SCENE city1 != the PVS bake's"),
    ("impostor-bake-job.yaml", "/data/shards/impostors-${JOB_COMPLETION_INDEX}",
     "/data/shards/pvs-${JOB_COMPLETION_INDEX}", "also takes impostor shards"),
    ("impostor-merge-job.yaml", "/data/shards/impostors-*-of-", "/data/shards/imp-*-of-",
     "does not read the bake's shards"),
    ("impostor-merge-job.yaml", 'value: "4"', 'value: "2"', "SHARDS 2 != the bake's 4"),
    ("impostor-merge-job.yaml", "-o /data/impostors.db", "-o /data/shards/impostors.db",
     "among the shards"),
    ("impostor-merge-job.yaml", "image: vistream:latest", "image: vistream:old", "different images"),
    ("impostor-merge-job.yaml", "mountPath: /data", "mountPath: /mnt", "different paths"),
]


def main():
    return planted_slips.run_slips("check_k8s_test", check_k8s.check, SOURCE, SLIPS)


if __name__ == "__main__":
    sys.exit(main())
