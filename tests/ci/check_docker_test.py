#!/usr/bin/env python3
"""Plants one slip at a time in copies of deploy/docker and deploy/haproxy and
expects check_docker.py to name it; the files as they are must pass."""

import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
import check_docker  # noqa: E402
import planted_slips  # noqa: E402

SOURCE = os.path.join(here, "..", "..", "deploy")

# (file under deploy/, text replaced, replacement, words the problem must contain)
SLIPS = [
    ("docker/Dockerfile", "FROM debian:12 AS run", "FROM debian:11 AS run", "debian:12"),
    ("docker/Dockerfile", "libzstd1 openmpi-bin", "libzstd-dev openmpi-bin", "-dev"),
    ("docker/Dockerfile", "USER 10001", "USER root", "as root"),
    ("docker/Dockerfile", "COPY --from=build", "COPY --from=elsewhere", "copies nothing"),
    ("haproxy/haproxy.cfg", "balance leastconn", "balance roundrobin", "leastconn"),
    ("haproxy/haproxy.cfg", "option httpchk GET /healthz", "option tcp-check", "/healthz"),
    ("haproxy/haproxy.cfg", "vistream-2:7070 port 8080", "vistream-2:7071 port 8080",
     "haproxy sends to 7071"),
    ("haproxy/haproxy.cfg", "    server vistream-2 ", "    server vistream-3 ", "compose runs"),
    ("docker/compose.yaml", '"--pvs-db", "/data/city1.pvsdb"', '"--pvs-db", "/data/other.pvsdb"',
     "the bake writes"),
    ("docker/compose.yaml", '"--host", "haproxy"', '"--host", "vistream-1"', "through haproxy"),
    ("docker/compose.yaml", "exec 3<>/dev/tcp/127.0.0.1/8080", "exec 3<>/dev/tcp/127.0.0.1/9090",
     "healthcheck"),
]


def main():
    return planted_slips.run_slips("check_docker_test", check_docker.check, SOURCE, SLIPS)


if __name__ == "__main__":
    sys.exit(main())
