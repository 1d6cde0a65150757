#!/usr/bin/env bash
# Installs what glradial needs from the system where it is missing (Debian/Ubuntu): the headless
# OpenGL libraries (EGL + Mesa llvmpipe), Python's venv module (Debian ships it separately), and the
# ffmpeg command the video tests compare against. Elsewhere it says what to install and carries on.
set -eu
PYTHON="${SYSPY:-python3}"
need=()
ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' || need+=(libegl1)
ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0' || need+=(libegl-mesa0 libgl1-mesa-dri)
ldconfig -p 2>/dev/null | grep -q 'libGL.so.1' || need+=(libgl1)
command -v ffmpeg >/dev/null 2>&1 || need+=(ffmpeg)
# glradial live relays srt:// through the system's ffmpeg (PyAV's wheels have no libsrt): Debian's has it
if command -v ffmpeg >/dev/null 2>&1 && ! ffmpeg -hide_banner -protocols 2>/dev/null | grep -qx '  srt'; then
  need+=(ffmpeg libsrt1.5-openssl)
fi
if ! "$PYTHON" -c 'import venv, ensurepip' >/dev/null 2>&1; then
  ver=$("$PYTHON" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
  need+=(python3-venv "python${ver}-venv")
fi
[ ${#need[@]} -eq 0 ] && exit 0
if command -v apt-get >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  # pythonX.Y-venv may not exist as a separate package on every release: install what exists.
  avail=()
  for p in "${need[@]}"; do
    if apt-cache show "$p" >/dev/null 2>&1; then avail+=("$p"); fi
  done
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${avail[@]}" >/dev/null
else
  echo "glradial: please install ${need[*]} (EGL, Mesa, ffmpeg, Python venv) with your package manager" >&2
fi
