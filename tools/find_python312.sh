#!/usr/bin/env bash
# Print the path of a working Python 3.12 interpreter, or explain what to do and exit 1.
# ROS 2 Jazzy's PyPI wheels (ros-jazzy-rclpy, ...) are built for CPython 3.12 only.
set -u
candidates=()
[ -n "${PYTHON312:-}" ] && candidates+=("$PYTHON312")
candidates+=(python3.12)
if command -v pyenv >/dev/null 2>&1; then
  root=$(pyenv root 2>/dev/null)
  for d in "$root"/versions/3.12*; do [ -x "$d/bin/python3.12" ] && candidates+=("$d/bin/python3.12"); done
fi
for d in "$HOME"/.pyenv/versions/3.12* /usr/local/bin /usr/bin; do
  [ -x "$d/bin/python3.12" ] && candidates+=("$d/bin/python3.12")
  [ -x "$d/python3.12" ] && candidates+=("$d/python3.12")
done
for c in "${candidates[@]}"; do
  # A pyenv shim exists even when 3.12 is not selected; only accept one that really runs 3.12.
  if out=$("$c" -c 'import sys; print(sys.executable if sys.version_info[:2] == (3, 12) else "")' 2>/dev/null) && [ -n "$out" ]; then
    echo "$out"; exit 0
  fi
done
cat >&2 <<'MSG'
error: no Python 3.12 interpreter found.
  cpg_walker needs CPython 3.12: the ROS 2 Jazzy wheels (ros-jazzy-rclpy) exist only for 3.12.
  Install one, then re-run make. For example:
    pyenv install 3.12        (then make finds it under $(pyenv root)/versions/3.12*)
    apt-get install python3.12 python3.12-venv   (where your distribution ships it)
  or point make at one:  make test PYTHON312=/path/to/python3.12
MSG
exit 1
