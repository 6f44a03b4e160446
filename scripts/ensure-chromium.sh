#!/bin/sh
# `make test` renders the report in headless Chromium: install Debian's `chromium` package when
# it is missing (as root, or through sudo), or say in one line what to do.
set -eu
if command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1; then
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "make test: Chromium is needed for the report test; install it (chromium on PATH) and rerun" >&2
  exit 1
fi
if [ "$(id -u)" -eq 0 ]; then
  SUDO=""
elif command -v sudo >/dev/null 2>&1; then
  SUDO="sudo"
else
  echo "make test: Chromium is needed for the report test; run 'apt-get install chromium' as root (no sudo here) and rerun" >&2
  exit 1
fi
echo "make test: installing Chromium (Debian package chromium) for the report test"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
