#!/usr/bin/env bash
# Installs the system libraries glradial needs for headless OpenGL (EGL + Mesa llvmpipe) where they
# are missing. Debian/Ubuntu only; elsewhere it says what to install and carries on.
set -eu
if ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0' \
   && ldconfig -p 2>/dev/null | grep -q 'libGL.so.1'; then
  exit 0
fi
if command -v apt-get >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 >/dev/null
else
  echo "glradial: install EGL and Mesa (libEGL.so.1, libEGL_mesa.so.0, libGL.so.1) with your package manager" >&2
fi
