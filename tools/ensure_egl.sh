#!/usr/bin/env bash
# Offscreen rendering (MUJOCO_GL=egl) needs Mesa's EGL. Install it from Debian's packages when it is
# missing and we may (root + apt-get); otherwise say what to install. Never fatal: only rendering needs it.
set -u
if ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0'; then
  exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "setup: installing Mesa EGL for offscreen rendering (apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri)"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libegl1 libegl-mesa0 libgl1-mesa-dri) >/dev/null \
    || echo "setup: warning: could not install Mesa EGL; offscreen rendering will be skipped" >&2
else
  echo "setup: warning: Mesa EGL not found; install libegl1 libegl-mesa0 libgl1-mesa-dri to render videos" >&2
fi
exit 0
