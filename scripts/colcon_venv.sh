#!/usr/bin/env bash
# The colcon venv: colcon-common-extensions and its dependencies (requirements/colcon.txt) in
# a venv of their own, .build/colcon-venv (FENCE_SORTER_COLCON_VENV), so that a colcon build of
# the workspace is tested apart from the project venv and its editable checkout
# (test/colcon/test_colcon_install.py). Idempotent: skipped when requirements/colcon.txt and
# the interpreter are what the venv was made with. Prints the venv's path.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${FENCE_SORTER_COLCON_VENV:-$ROOT/.build/colcon-venv}"
BASE="${PYTHON:-python3.11}"
REQ="$ROOT/requirements/colcon.txt"

key="$({ sha256sum <"$REQ"; "$BASE" -V 2>&1; } | sha256sum | cut -d' ' -f1)"
if [[ "${FENCE_SORTER_FORCE:-0}" != 1 && -x "$VENV/bin/colcon" && -f "$VENV/.stamp" &&
  "$(<"$VENV/.stamp")" == "$key" ]]; then
  echo "$VENV"
  exit 0
fi
echo "colcon_venv: creating $VENV (requirements/colcon.txt)" >&2
rm -rf "$VENV"
"$BASE" -m venv "$VENV"
"$VENV/bin/python" -m pip --disable-pip-version-check install --quiet -r "$REQ" \
  2> >(grep -v -- 'is ignored: it is neither a file nor a directory' >&2)
printf '%s\n' "$key" >"$VENV/.stamp"
echo "$VENV"
