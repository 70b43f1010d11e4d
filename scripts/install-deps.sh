#!/usr/bin/env bash
# Installs exactly the Debian packages mcslam builds and tests with. Idempotent: packages already
# present are skipped without touching apt, so a second run costs nothing.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  libopencv-dev libeigen3-dev libceres-dev libtbb-dev
  libcli11-dev libspdlog-dev nlohmann-json3-dev libyaml-cpp-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-matplotlib python3-numpy
  clang libclang-rt-14-dev libomp-14-dev
  libjs-three chromium
)
# clang and its runtime libraries (libFuzzer, the sanitizers) build the fuzz targets (scripts/fuzz.sh) and the
# sanitized tests (make test-sanitize), which also need clang's OpenMP runtime (libomp-14-dev). libjs-three is
# the WebGL library the viewer's page inlines (mcslam view, run --viewer); chromium opens that page headless in
# its test (CliView.*).

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "install-deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
