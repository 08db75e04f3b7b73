#!/usr/bin/env bash
# Installs exactly the Debian 12 packages flexbench needs that are missing. Non-interactive and
# idempotent: with everything present it only checks. Runs `apt-get update` once, and only when
# something has to be installed. Stops with a clear message when it cannot install.
set -euo pipefail

PACKAGES=(
  cmake g++ make pkg-config
  libmujoco-dev libqhull-dev      # MuJoCo 2.2.2; its CMake config names qhull's include dir
  libeigen3-dev                   # Eigen 3.4
  libosmesa6-dev                  # headless OpenGL (Mesa's software rasteriser)
  libopencv-dev                   # OpenCV 4.6 (imgproc, imgcodecs, calib3d)
  libapriltag-dev apriltag        # AprilTag 3.3 (libapriltag + libapriltag-utils)
  libgtest-dev libbenchmark-dev   # GoogleTest, Google Benchmark
  libyaml-cpp-dev nlohmann-json3-dev libcli11-dev
  slurmctld slurmd slurm-client munge procps   # a real single-node Slurm for the sweep tests
  clang-format                    # scripts/check_format.sh (CI)
  chromium                        # headless browser that renders report.html in its test
  pybind11-dev python3-pybind11 python3-dev python3-numpy python3-pytest   # the Python module + tests
)

missing=()
for pkg in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#PACKAGES[@]} packages present"
  exit 0
fi

echo "setup: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO="sudo"
  else
    echo "setup: error: missing packages (${missing[*]}) and not root; install them with apt-get" >&2
    exit 1
  fi
fi
if ! $SUDO apt-get update -qq; then
  echo "setup: error: 'apt-get update' failed; cannot install ${missing[*]}" >&2
  exit 1
fi
if ! DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
    "${missing[@]}" >/dev/null; then
  echo "setup: error: apt-get could not install: ${missing[*]}" >&2
  exit 1
fi
echo "setup: installed ${#missing[@]} packages"
