#!/bin/sh
# verify-unit.sh UNIT_FILE: `systemd-analyze verify` a unit file, failing on
# any complaint about it.  Drop-ins in UNIT_FILE.d/ next to it are verified
# with it.  Exit 77 (ctest: skipped) when systemd-analyze is not installed.
set -u

if [ $# -ne 1 ]; then
  echo "usage: $0 UNIT_FILE" >&2
  exit 2
fi
unit=$1

if ! command -v systemd-analyze >/dev/null 2>&1; then
  echo "systemd-analyze not found: skipping"
  exit 77
fi
if [ ! -f "$unit" ]; then
  echo "$0: $unit: no such file" >&2
  exit 1
fi

# --man=no: no man-page lookups; --recursive-errors=no: judge this unit, not
# the host's network-online.target/multi-user.target (older systemd lacks it).
set -- --man=no
if systemd-analyze --help 2>/dev/null | grep -q -- '--recursive-errors'; then
  set -- "$@" --recursive-errors=no
fi

echo "+ systemd-analyze verify $* $unit"
out=$(systemd-analyze verify "$@" "$unit" 2>&1)
rc=$?
[ -n "$out" ] && printf '%s\n' "$out"

# verify exits 0 on mere warnings (unknown keys, bad values it ignores), so
# any line naming our unit or drop-in counts as a failure too.
name=$(basename "$unit")
if [ $rc -ne 0 ]; then
  echo "FAIL: systemd-analyze verify exited $rc"
  exit 1
fi
if printf '%s\n' "$out" | grep -q -F -e "$name" -e "$unit"; then
  echo "FAIL: systemd-analyze verify reported problems with $name"
  exit 1
fi
echo "OK: $unit"
