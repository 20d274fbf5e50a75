#!/usr/bin/env bash
# Run a command with some programs hidden from it, as on a machine where they were never
# installed: the PATH is replaced by one directory of links to every program of the
# PATH except the named ones. .ci/run uses it to run the README's test command once
# without Graphviz and Chromium, whether or not this machine has them.
#   bash tools/without-programs.sh dot chromium -- bash -c 'python3 -m pytest'
set -euo pipefail

hidden=()
while [ $# -gt 0 ] && [ "$1" != -- ]; do hidden+=("$1"); shift; done
if [ $# -lt 2 ]; then
  echo "usage: $0 PROGRAM... -- COMMAND [ARG...]" >&2
  exit 2
fi
shift

bin=$(mktemp -d "${TMPDIR:-/tmp}/sotpy-path.XXXXXX")
trap 'rm -rf "$bin"' EXIT
IFS=: read -r -a dirs <<<"$PATH"
for dir in "${dirs[@]}"; do
  [ -d "$dir" ] || continue
  for exe in "$dir"/*; do
    name=${exe##*/}
    [ -x "$exe" ] && [ ! -d "$exe" ] || continue
    [ -e "$bin/$name" ] && continue # the first one on the PATH wins, as before
    skip=
    for h in "${hidden[@]}"; do [ "$name" = "$h" ] && skip=1; done
    [ -n "$skip" ] || ln -s "$exe" "$bin/$name"
  done
done
for h in "${hidden[@]}"; do
  if PATH=$bin command -v "$h" >/dev/null 2>&1; then
    echo "$0: could not hide $h" >&2
    exit 1
  fi
done
PATH=$bin "$@"
