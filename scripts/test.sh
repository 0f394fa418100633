#!/usr/bin/env bash
# Builds minemap and runs every test: a check that the build used only packages install-deps.sh
# installs (scripts/check-deps.sh), the unit tests (OpenCL ones on PoCL, failing when no OpenCL
# platform is found), the fuzz corpora, the Python package (pip install . from the same build, into
# build/venv) and its pytest suite, the unit tests again under ASan+UBSan and under TSan
# (scripts/sanitize.sh; the TSan build is also the -march=native one, where the backend-agreement
# tests prove that the CPU's poses stay the OpenCL kernels' with FMA on offer), and a short libFuzzer
# run of every parser.
# Usage: scripts/test.sh   (SANITIZERS=0 skips the sanitizer runs and with them the -march=native
#                          build, FUZZ_SECONDS=0 the libFuzzer run)
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh test
started=$SECONDS
stage() { echo "--- $* (at $(( (SECONDS - started) / 60 )) min $(( (SECONDS - started) % 60 )) s)"; }
stage "OpenCL platforms"
clinfo -l || true
jobs="$(nproc)"
# The Python package's build and test tools, pinned, in a virtualenv inside the build folder (Debian's
# Python refuses pip installs outside one, PEP 668).
stage "Python virtualenv build/venv (python/requirements-test.txt from PyPI)"
# Debian's Python (python3-dev, python3-venv: install-deps.sh), not whichever python3 is first on
# PATH (a pyenv's headers would come from no package: check-deps.sh refuses them).
[ -x build/venv/bin/python ] || /usr/bin/python3 -m venv build/venv
# pip trusts the system's certificate authorities (ca-certificates, and what the administrator added:
# a proxy's), not only its own copy of Mozilla's.
if [ -z "${PIP_CERT:-}" ] && [ -f /etc/ssl/certs/ca-certificates.crt ]; then export PIP_CERT=/etc/ssl/certs/ca-certificates.crt; fi
build/venv/bin/pip install -q --disable-pip-version-check -r python/requirements-test.txt
# One build for the program, the tests and the Python extension: `pip install .` below reuses it.
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DMINEMAP_BUILD_BENCH=ON -DMINEMAP_BUILD_PYTHON=ON \
  -DPython_EXECUTABLE="$PWD/build/venv/bin/python" -Dpybind11_DIR="$(build/venv/bin/python -m pybind11 --cmakedir)"
cmake --build build -j"$jobs"
stage "the build used only what 'scripts/install-deps.sh build' installs"
scripts/check-deps.sh build build
stage "unit tests"
(cd build && ctest --output-on-failure -j"$jobs" --timeout 900)
stage "Python package: pip install . (into build/venv, from the same build), then pytest"
CMAKE_GENERATOR="Unix Makefiles" build/venv/bin/pip install -q --no-build-isolation --no-deps \
  --config-settings=build-dir=build .
(cd python/tests && MINEMAP_CLI="$PWD/../../build/minemap" ../../build/venv/bin/python -m pytest -q -p no:cacheprovider .)
fuzz_build_dir=build-fuzz
if [ "${SANITIZERS:-1}" != "0" ]; then
  stage "unit tests under ASan+UBSan and TSan"
  scripts/sanitize.sh all
  # The fuzz targets need the same library build (clang, address+undefined, RelWithDebInfo): reuse it.
  fuzz_build_dir=build-asan
fi
if [ "${FUZZ_SECONDS:-5}" != "0" ]; then
  stage "libFuzzer, ${FUZZ_SECONDS:-5} s per parser"
  FUZZ_BUILD_DIR="$fuzz_build_dir" scripts/fuzz.sh
fi
