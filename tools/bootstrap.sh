#!/usr/bin/env bash
# One-step set-up for a fresh Debian 12 machine: installs what octocosm needs
# (apt-get), builds it, and then either runs the demo job or the whole test
# suite. Idempotent: packages already present are not fetched again.
#
#   tools/bootstrap.sh demo   # install, build, run the main job on an embedded default
#   tools/bootstrap.sh test   # install, build (plain + ASan/UBSan), run every test
set -euo pipefail

mode="${1:-demo}"
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
jobs="$(nproc 2>/dev/null || echo 2)"

packages=(
  build-essential cmake pkg-config git
  libhdf5-dev libzstd-dev libxxhash-dev libfftw3-dev
  libcli11-dev nlohmann-json3-dev
  # k-nearest-neighbour smoothing lengths (the reference and ingest)
  libnanoflann-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  # renderer: OpenGL 4.5 core through OSMesa (headless) or GLFW (windows), a GL
  # loader generated at build time by glad, Dear ImGui, PNG output, Xvfb for the
  # viewer's tests, EGL for headless rendering on a real GPU
  libosmesa6-dev libglfw3-dev libglm-dev python3-glad libimgui-dev libpng-dev libegl-dev
  xvfb xauth
  # the viewer's test plays mouse and keyboard input into Xvfb through XTEST
  libxtst-dev
  # accuracy cross-checks against the Point Cloud Library
  libpcl-dev
  # benchmarks draw their plots with gnuplot
  gnuplot-nox
  # clang, for the test that runs its thread-safety analysis (docs/TESTING.md)
  clang
  # the Python module (python/), its pytest suite and its example's plot
  pybind11-dev python3-dev python3-numpy python3-pytest python3-matplotlib
  # pip install of the source path into a virtual environment
  python3-venv python3-pip python3-wheel
  # stores read over HTTP(S) with range requests; the tests serve them with nginx
  libcurl4-openssl-dev nginx-light
  # ingest spread over processes with mpirun (Open MPI)
  openmpi-bin libopenmpi-dev
  # Not here: libclang-rt-14-dev, which only the long libFuzzer runs need
  # (docs/TESTING.md); CI runs the fuzz targets under our own driver.
)

install_packages() {
  local missing=()
  for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]} == 0)); then
    echo "bootstrap: all ${#packages[@]} packages present"
    return
  fi
  echo "bootstrap: installing ${missing[*]}"
  local sudo=""
  if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

build() {  # build DIR [cmake args...]
  local dir="$1"; shift
  cmake -S "$root" -B "$dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo "$@" >/dev/null
  cmake --build "$dir" -j"$jobs"
}

install_packages
case "$mode" in
  demo)
    build "$root/build"
    "$root/tools/demo.sh" "$root/build"
    ;;
  test)
    build "$root/build"
    (cd "$root/build" && ctest --output-on-failure -j"$jobs")
    # The same suite once more under AddressSanitizer + UndefinedBehaviorSanitizer.
    build "$root/build-asan" -DOCTOCOSM_SANITIZE=ON -DOCTOCOSM_BUILD_BENCH=OFF
    (cd "$root/build-asan" && ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
       ctest --output-on-failure -j"$jobs")
    ;;
  *)
    echo "usage: $0 demo|test" >&2
    exit 2
    ;;
esac
