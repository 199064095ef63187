#!/usr/bin/env python3
"""Checks deploy/docker and deploy/haproxy against each other and the tools.

  - Dockerfile: a build stage and a run stage, both on debian:12; the run
    stage installs no -dev package, copies the tools from the build stage and
    runs as a non-root user; with --bin DIR, every shared library the built
    tools name (ELF NEEDED) belongs to a package the run stage installs (or
    to debian:12's base: libc6, libgcc-s1, libstdc++6);
  - compose.yaml: redis, the bake, two replicas, haproxy and the load test;
    the replicas serve the database the bake writes (same volume and path),
    listen where haproxy.cfg sends clients and health checks, and check
    their own /healthz;
  - haproxy.cfg: TCP mode, leastconn, HTTP health checks on /healthz, one
    server line per replica.

Usage: check_docker.py [--deploy DIR] [--bin DIR]. Prints one line per
problem and exits 1 if there is any.
"""

import argparse
import os
import re
import shlex
import subprocess
import sys

import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from planted_slips import Problems  # noqa: E402

BASE_PACKAGES = {"libc6", "libgcc-s1", "libstdc++6"}
TOOLS = ["vistream-server", "vistream-pvs", "vistream-loadtest", "vistream-scene"]


def stages(dockerfile):
    """[(name, base, text)] of the Dockerfile's stages, continuation lines joined."""
    text = re.sub(r"\\\n", " ", dockerfile)
    out = []
    for line in text.splitlines():
        m = re.match(r"FROM\s+(\S+)(?:\s+AS\s+(\S+))?", line.strip(), re.I)
        if m:
            out.append([m.group(2) or "", m.group(1), ""])
        elif out:
            out[-1][2] += line + "\n"
    return [tuple(s) for s in out]


def apt_packages(stage_text):
    packages = set()
    for m in re.finditer(r"apt-get install ([^&|;]*)", stage_text):
        packages |= {w for w in m.group(1).split() if not w.startswith("-")}
    return packages


def needed_packages(bin_dir):
    """Debian packages of the shared libraries the tools name, or None if unknown."""
    packages = set()
    for tool in TOOLS:
        path = os.path.join(bin_dir, tool)
        needed = re.findall(r"\(NEEDED\).*\[(.+)\]",
                            subprocess.run(["readelf", "-d", path], capture_output=True,
                                           text=True, check=True).stdout)
        resolved = {}
        for line in subprocess.run(["ldd", path], capture_output=True, text=True,
                                   check=True).stdout.splitlines():
            m = re.match(r"\s*(\S+) => (\S+)", line)
            if m:
                resolved[m.group(1)] = m.group(2)
        for lib in needed:
            where = resolved.get(lib, lib)
            # Debian 12 merges /lib into /usr/lib: dpkg knows one of the two names.
            candidates = {where, os.path.realpath(where)}
            candidates |= {"/usr" + c for c in candidates if c.startswith("/lib")}
            candidates |= {c[len("/usr"):] for c in candidates if c.startswith("/usr/lib")}
            owner = None
            for c in sorted(candidates):
                r = subprocess.run(["dpkg", "-S", c], capture_output=True, text=True)
                if r.returncode == 0:
                    owner = r.stdout.split(":")[0]
                    break
            packages.add(owner or f"? {lib} ({where})")
    return packages


def check(deploy, bin_dir=None):
    problems = Problems()
    need = problems.need

    try:
        with open(os.path.join(deploy, "docker", "Dockerfile"), encoding="utf-8") as f:
            dockerfile = f.read()
        with open(os.path.join(deploy, "docker", "compose.yaml"), encoding="utf-8") as f:
            compose = yaml.safe_load(f)
        with open(os.path.join(deploy, "haproxy", "haproxy.cfg"), encoding="utf-8") as f:
            haproxy = f.read()
    except (OSError, yaml.YAMLError) as e:
        return [f"cannot read deploy/: {e}"]

    # Dockerfile.
    st = stages(dockerfile)
    if need(len(st) == 2, f"Dockerfile: expected a build and a run stage, found {len(st)}"):
        (build_name, build_base, _), (_, run_base, run_text) = st
        need(build_base == "debian:12" and run_base == "debian:12",
             f"Dockerfile: stages must be on debian:12, not {build_base} and {run_base}")
        run_packages = apt_packages(run_text)
        dev = sorted(p for p in run_packages if p.endswith("-dev"))
        need(not dev, f"Dockerfile: the run stage installs -dev packages: {dev}")
        need(re.search(rf"COPY\s+--from={re.escape(build_name)}\s", run_text) is not None,
             "Dockerfile: the run stage copies nothing from the build stage")
        users = re.findall(r"^USER\s+(\S+)", run_text, re.M)
        need(users and users[-1] not in ("0", "root"), "Dockerfile: the run stage runs as root")
        if bin_dir:
            missing = sorted(needed_packages(bin_dir) - run_packages - BASE_PACKAGES)
            need(not missing, f"Dockerfile: the run stage lacks packages the tools need: {missing}")

    # haproxy.cfg.
    need(re.search(r"^\s*mode tcp", haproxy, re.M) is not None, "haproxy.cfg: not in TCP mode")
    need(re.search(r"^\s*balance leastconn", haproxy, re.M) is not None,
         "haproxy.cfg: the backend does not balance by leastconn")
    need(re.search(r"option httpchk GET /healthz", haproxy) is not None,
         "haproxy.cfg: health is not checked on /healthz")
    servers = {m.group(1): (m.group(2), int(m.group(3)), int(m.group(4)))
               for m in re.finditer(r"^\s*server (\S+) ([\w.-]+):(\d+) port (\d+)", haproxy, re.M)}
    frontend = re.search(r"frontend vistream_stream\s*\n\s*bind :(\d+)", haproxy)

    # compose.yaml.
    services = compose.get("services", {})
    for name in ("redis", "bake", "haproxy", "loadtest"):
        need(name in services, f"compose.yaml: no {name} service")
    replicas = sorted(n for n in services if n.startswith("vistream-"))
    need(len(replicas) >= 2, f"compose.yaml: expected two replicas, found {replicas}")
    need(sorted(servers) == replicas,
         f"haproxy.cfg serves {sorted(servers)}, compose runs {replicas}")
    bake_cmd = services.get("bake", {}).get("command", [])
    bake_out = bake_cmd[bake_cmd.index("--out") + 1] if "--out" in bake_cmd else None
    for name in replicas:
        svc = services[name]
        cmd = svc.get("command", [])

        def arg(flag):
            return cmd[cmd.index(flag) + 1] if flag in cmd else None

        need(arg("--pvs-db") == bake_out,
             f"compose.yaml: {name} serves {arg('--pvs-db')}, the bake writes {bake_out}")
        if name in servers:
            host, port, check_port = servers[name]
            need(host == name, f"haproxy.cfg: server {name} points at {host}")
            need(arg("--port") == str(port),
                 f"compose.yaml: {name} listens on {arg('--port')}, haproxy sends to {port}")
            need(arg("--http-port") == str(check_port),
                 f"compose.yaml: {name} has HTTP on {arg('--http-port')}, haproxy checks {check_port}")
        test = " ".join(svc.get("healthcheck", {}).get("test", []))
        need(f"127.0.0.1/{arg('--http-port')}" in test and "/healthz" in test,
             f"compose.yaml: {name}'s healthcheck does not ask its own /healthz")
        need(svc.get("depends_on", {}).get("bake", {}).get("condition") ==
             "service_completed_successfully",
             f"compose.yaml: {name} does not wait for the bake")
    lt = services.get("loadtest", {}).get("command", [])
    need("--host" in lt and lt[lt.index("--host") + 1] == "haproxy",
         "compose.yaml: the load test does not go through haproxy")
    if frontend and "--port" in lt:
        need(lt[lt.index("--port") + 1] == frontend.group(1),
             "compose.yaml: the load test's port is not haproxy's")
    mounts = " ".join(services.get("haproxy", {}).get("volumes", []))
    need("../haproxy/haproxy.cfg:" in mounts, "compose.yaml: haproxy does not mount haproxy.cfg")
    return problems


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--deploy", default=os.path.join(here, "..", "..", "deploy"))
    parser.add_argument("--bin", help="the built tools, to check the run stage's packages")
    args = parser.parse_args()
    problems = check(args.deploy, args.bin)
    for p in problems:
        print(f"check_docker: {p}")
    if not problems:
        print("check_docker: Dockerfile, compose.yaml and haproxy.cfg agree")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
