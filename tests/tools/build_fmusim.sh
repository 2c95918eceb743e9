#!/usr/bin/env bash
# Build fmusim, the FMI 1.0/2.0/3.0 importer of the Modelica Association's Reference-FMUs, from source:
# an FMI 3.0 importer independent of fmpy, for tests/test_fmi3_export.py.
#
# Usage: build_fmusim.sh [PREFIX]          (default PREFIX: $HOME/.cache/fmugen/fmusim)
# Env:   REFERENCE_FMUS_SRC_GIT  a local git repo of github.com/modelica/Reference-FMUs (no network then);
#                                unset -> cloned from GitHub.
#        REFERENCE_FMUS_REF      default c8d4e6d90fa14be49d7622badf30e38eebea5e0a, the last commit with
#                                fmusim/ in that repository (v0.0.39 of its GUI; fmusim moved out after it)
# Needs gcc and the development packages of libxml2, minizip, zlib and SUNDIALS' CVODE (installed with
# apt when missing). Compiled with one gcc call instead of the repository's CMake, which expects
# dependencies it builds itself under build/. Prints the path of the built binary on the last line.
set -euo pipefail

PREFIX=$(mkdir -p "${1:-$HOME/.cache/fmugen/fmusim}" && cd "${1:-$HOME/.cache/fmugen/fmusim}" && pwd)
REF=${REFERENCE_FMUS_REF:-c8d4e6d90fa14be49d7622badf30e38eebea5e0a}

if ! { [ -f /usr/include/libxml2/libxml/parser.h ] && [ -f /usr/include/minizip/unzip.h ] &&
       [ -f /usr/include/cvode/cvode.h ] && command -v gcc >/dev/null; }; then
  SUDO=$([ "$(id -u)" -eq 0 ] || echo sudo)
  $SUDO apt-get update -q && $SUDO apt-get install -y -q gcc git libxml2-dev libminizip-dev zlib1g-dev libsundials-dev
fi

WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
if [ -z "${REFERENCE_FMUS_SRC_GIT:-}" ]; then
  REFERENCE_FMUS_SRC_GIT=$WORK/reference-fmus.git
  git clone -q --bare https://github.com/modelica/Reference-FMUs "$REFERENCE_FMUS_SRC_GIT"
fi
mkdir -p "$WORK/src"
git -C "$REFERENCE_FMUS_SRC_GIT" archive "$REF" fmusim include src | tar -x -C "$WORK/src"

cd "$WORK/src/fmusim"
# SUN_COMM_NULL is SUNDIALS 7's name of the null communicator; Debian 12 has SUNDIALS 6, where it is NULL.
gcc -O2 -w -std=gnu11 -DSUN_COMM_NULL=NULL -DFMUSIM_VERSION=\"reference-fmus-${REF:0:7}\" \
  -I. -I../include -I/usr/include/libxml2 -I/usr/include/minizip \
  ./*.c ../src/FMI.c ../src/FMI1.c ../src/FMI2.c ../src/FMI3.c \
  ../src/structured_variable_name.yy.c ../src/structured_variable_name.tab.c \
  -o "$PREFIX/fmusim" -lxml2 -lminizip -lz -lsundials_cvode -lsundials_nvecserial -lm -ldl
"$PREFIX/fmusim" --version >/dev/null
echo "$PREFIX/fmusim"
