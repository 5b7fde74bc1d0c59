#!/usr/bin/env bash
# Installs everything desplat needs on a fresh Debian 12 (bookworm) machine.
# Non-interactive; run as root (or with sudo available).
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update
# openmpi-bin, libopenmpi-dev: the MPI communicator (optional at build time, the comm layer).
# python3-pil: the effect bench's summary (data/synthetic/effects/summarize.py) draws its plot.
$SUDO apt-get install -y --no-install-recommends \
  build-essential cmake ninja-build pkg-config git ca-certificates \
  libeigen3-dev libglm-dev libceres-dev \
  libopencv-dev libopenimageio-dev openimageio-tools \
  libgtest-dev libgmock-dev libbenchmark-dev \
  nlohmann-json3-dev libcli11-dev libnanoflann-dev libsqlite3-dev \
  colmap clang clang-format libclang-rt-14-dev libomp-dev \
  gnuplot-nox chromium python3-pil \
  openmpi-bin libopenmpi-dev
