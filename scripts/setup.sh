#!/usr/bin/env bash
# Installs what is missing (Debian 12 packages only) and builds brickcast into ./build.
# Used by both README commands and by CI; safe to run again (it only installs what lacks).
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake pkg-config ninja-build
  libopenvdb-dev libboost-iostreams-dev libtbb-dev   # OpenVDB reader (+ what FindOpenVDB needs)
  libzstd-dev zstd libxxhash-dev zlib1g-dev           # brick compression, checksums, gzip input
  libnifti2-dev libgdcm-dev                           # NIfTI-1 and DICOM readers
  libtiff-dev libhdf5-dev libblosc-dev libexpat1-dev  # TIFF, HDF5, Zarr (blosc chunks) and .vti readers
  python3-numpy python3-tifffile python3-zarr python3-numcodecs python3-h5py python3-vtk9 libtiff-tools  # the readers' tests: independent writers (tiffcp: LZW and zstd TIFFs)
  nlohmann-json3-dev libcli11-dev                     # info --json, command line
  libegl-dev libgl-dev libopengl-dev libegl-mesa0 libgl1-mesa-dri  # headless OpenGL 4.5 (llvmpipe without a GPU)
  libglm-dev libpng-dev                               # vector maths, PNG images
  libhwy-dev                                          # Highway: the CPU raycaster's SIMD
  libopenmpi-dev openmpi-bin                          # OpenMPI: sort-last scale-out over ranks (mpirun)
  libboost-dev libtomlplusplus-dev libturbojpeg0-dev  # brickcastd: Asio + Beast (network, HTTP, WebSocket), config file, JPEG frames
  libssl-dev openssl                                  # TLS (server, thin client); tests make self-signed certificates
  libgtest-dev libgmock-dev clang libclang-rt-14-dev  # tests (GoogleTest, GoogleMock); the fuzzers (libFuzzer)
  clang-format                                        # the formatting check (test clang_format)
  gnuplot-nox                                         # bc_bench_render --plot
  chromium                                            # the browser viewer's tests (tests/browser)
  mkdocs mkdocs-material                              # the documentation site (docs/, test docs_site)
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Node.js with npm (the viewer's unit tests and playwright-core): Debian's, unless the machine
# has one already (a NodeSource nodejs brings its own npm and conflicts with Debian's).
command -v npm >/dev/null || missing+=(nodejs npm)
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# playwright-core for the browser tests, exactly as tests/browser/package-lock.json pins it (it
# drives Debian's chromium; no browser is downloaded).
if [[ ! -d tests/browser/node_modules/playwright-core ||
      tests/browser/node_modules -ot tests/browser/package-lock.json ]]; then
  (cd tests/browser && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund --silent &&
    touch node_modules)
fi

cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j"$(nproc)"
