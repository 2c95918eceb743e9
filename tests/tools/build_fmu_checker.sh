#!/usr/bin/env bash
# Build the FMI Compliance Checker (fmuCheck.<platform>) from source, with FMI Library (FMIL) 2.0.x.
#
# Usage: build_fmu_checker.sh [PREFIX]          (default PREFIX: $HOME/.cache/fmugen/fmuchecker)
# Env:   FMUCHECK_SRC_GIT / FMIL_SRC_GIT  local git repos to build from (no network needed then);
#                                         unset -> cloned from GitHub.
#        FMUCHECK_REF (default HEAD), FMIL_REF (default 2.0.3, the FMIL the checker is written for),
#        JOBS (default: nproc)
# Prints the path of the built binary on the last line.
set -euo pipefail

PREFIX=$(mkdir -p "${1:-$HOME/.cache/fmugen/fmuchecker}" && cd "${1:-$HOME/.cache/fmugen/fmuchecker}" && pwd)
FMUCHECK_REF=${FMUCHECK_REF:-HEAD}
FMIL_REF=${FMIL_REF:-2.0.3}
JOBS=${JOBS:-$(nproc)}

# Install only the build tools that are missing (apt, with sudo when not root).
missing=()
for t in cmake g++ make git; do command -v "$t" >/dev/null || missing+=("$t"); done
if ((${#missing[@]})); then
  SUDO=$([ "$(id -u)" -eq 0 ] || echo sudo)
  $SUDO apt-get update -q && $SUDO apt-get install -y -q "${missing[@]}"
fi

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT

# Get the repos: use the given local ones, else clone bare copies (the only network step).
if [ -z "${FMUCHECK_SRC_GIT:-}" ]; then
  FMUCHECK_SRC_GIT=$WORK/checker.git
  git clone -q --bare https://github.com/modelica-tools/FMUComplianceChecker "$FMUCHECK_SRC_GIT"
fi
if [ -z "${FMIL_SRC_GIT:-}" ]; then
  FMIL_SRC_GIT=$WORK/fmil.git
  git clone -q --bare https://github.com/modelon-community/fmi-library "$FMIL_SRC_GIT"
fi

# Export plain source trees (repos may have no work tree). The checker's CMakeLists expects
# FMIL at <checker>/FMIL, so put it there.
SRC=$WORK/src
mkdir -p "$SRC/FMIL"
git -C "$FMUCHECK_SRC_GIT" archive "$FMUCHECK_REF" | tar -x -C "$SRC"
git -C "$FMIL_SRC_GIT" archive "$FMIL_REF" | tar -x -C "$SRC/FMIL"

# Patch the checker's CMakeLists (temp copy only):
#  - ExternalProject would git-clone FMIL from GitHub: replace the download by a no-op,
#    so it builds the tree exported above;
#  - version strings come from `svn info` (else "Test"): set them from the git refs instead.
CHK_VER=$(git -C "$FMUCHECK_SRC_GIT" describe --tags --always "$FMUCHECK_REF")
sed -i \
  -e 's|^\s*GIT_REPOSITORY .*|\tDOWNLOAD_COMMAND ""|' \
  -e '/^\s*GIT_TAG /d' \
  -e "s|^getVersionSVN(\"\${FMUCHK_HOME}\" FMUCHK_VERSION)|set(FMUCHK_VERSION \"$CHK_VER\")|" \
  -e "s|^getVersionSVN(\"\${FMUCHK_HOME}/FMIL\" FMIL_VERSION)|set(FMIL_VERSION \"$FMIL_REF\")|" \
  "$SRC/CMakeLists.txt"
grep -q 'DOWNLOAD_COMMAND ""' "$SRC/CMakeLists.txt"   # fail loudly if the patch no longer applies

# FMIL 2.0.x's CMake code reads the LOCATION of targets (policy CMP0026 OLD), which CMake >= 4
# no longer allows, so use a CMake 3.x: the one on PATH, else /usr/bin's, else one from PyPI.
CMAKE=
for c in "$(command -v cmake)" /usr/bin/cmake; do
  if "$c" --version 2>/dev/null | grep -q 'version 3\.'; then CMAKE=$c; break; fi
done
if [ -z "$CMAKE" ]; then
  python3 -m pip install -q --target "$WORK/cmake3" 'cmake>=3.16,<4'
  CMAKE=$WORK/cmake3/cmake/data/bin/cmake
fi

# Configure, build (FMIL first via ExternalProject, then the checker) and install into PREFIX.
"$CMAKE" -S "$SRC" -B "$WORK/build" -DCMAKE_BUILD_TYPE=Release -DFMUCHK_INSTALL_PREFIX="$PREFIX"
"$CMAKE" --build "$WORK/build" -j "$JOBS"
"$CMAKE" --install "$WORK/build"

BIN=$(find "$PREFIX" -maxdepth 2 -type f -name 'fmuCheck.*' -perm -u+x | head -n1)
[ -n "$BIN" ] || { echo "fmuCheck binary not found in $PREFIX" >&2; exit 1; }
echo "$BIN"
