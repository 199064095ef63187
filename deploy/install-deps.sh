#!/usr/bin/env bash
# Installs every Debian 12 package that vistream's build, tests and demo need.
# Idempotent and non-interactive: packages already present are skipped, so a
# second run costs one dpkg query. Runs as root, or through sudo when present.
set -euo pipefail

packages=(
  # toolchain
  build-essential cmake ninja-build pkg-config git clang clang-format libclang-rt-14-dev
  # libraries found by CMake
  libboost-dev libflatbuffers-dev flatbuffers-compiler libglm-dev libglfw3-dev
  libembree-dev libspdlog-dev libfmt-dev libtbb-dev libepoxy-dev
  libgtest-dev libgmock-dev libbenchmark-dev libcli11-dev nlohmann-json3-dev
  libtinyobjloader-dev libtinygltf-dev libstb-dev libmeshoptimizer-dev libzstd-dev
  # the bake over MPI ranks (vistream-pvs bake --mpi, mpirun)
  libopenmpi-dev openmpi-bin
  # shared presence between server replicas (--presence redis://; the scale test)
  libhiredis-dev redis-server redis-tools
  # headless OpenGL for tests (Mesa llvmpipe under Xvfb)
  xvfb xauth libgl1-mesa-dri libgl1-mesa-dev
  # plots in benchmarks; the demo's result check; deploy recipes' checks
  gnuplot-nox python3 python3-yaml yamllint haproxy systemd
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi

echo "install-deps: installing ${#missing[@]} missing packages: ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    echo "install-deps: not root and no sudo; install these packages: ${missing[*]}" >&2
    exit 1
  fi
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
