#!/bin/bash
# Loop-jitter benchmark (not a test): wake-up latency of the pvcgeld loop beside
# cyclictest's, same priority and period, idle and under stress-ng CPU load.
# Only ratios from the same run mean anything on a virtual, non-RT machine.
#
# Usage: benchmarks/loop_jitter.sh [BUILD_DIR] [SECONDS]   (as root for SCHED_FIFO)
# Needs Debian rt-tests (cyclictest) and stress-ng.
set -euo pipefail
BUILD=${1:-build}
SECONDS_EACH=${2:-20}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PRIO=80
PERIOD_US=1000
for tool in cyclictest stress-ng; do
  command -v $tool >/dev/null || { echo "loop_jitter: $tool missing (apt-get install rt-tests stress-ng)"; exit 1; }
done
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"; kill $(jobs -p) 2>/dev/null || true' EXIT

# p50 p99 p99.9 max (us) from cyclictest's histogram (-h): lines "USEC COUNT". A quantile beyond the
# histogram's 5000 us is reported as 5000, as the daemon's own histogram does.
cyclic_stats() {
  cyclictest -m -q -p $PRIO -i $PERIOD_US -l $((SECONDS_EACH * 1000000 / PERIOD_US)) -h 5000 > "$TMP/ct.txt" 2>&1
  awk '/^[0-9]+[ \t]/ { n[$1+0] = $2; total += $2 }
       /# Max Latencies/ { max = $4 + 0 }
       /# Histogram Overflows/ { total += $4 }
       END { split("0.5 0.99 0.999", q, " "); acc = 0; i = 1;
             for (us = 0; us < 5000 && i <= 3; us++) { acc += n[us];
               while (i <= 3 && acc >= q[i] * total) { r[i] = us; i++ } }
             for (; i <= 3; i++) r[i] = 5000;  # in the overflow: the histogram edge, as pvcgeld reports it
             printf "%d %d %d %d\n", r[1], r[2], r[3], max }' "$TMP/ct.txt"
}
# Same quantiles from the daemon's own histogram (its exit summary line).
daemon_stats() {
  "$ROOT/$BUILD/daemon/pvcgeld" --config "$ROOT/config/pvcgeld-sim.toml" --trajectory paper-1hz \
      --duration "$SECONDS_EACH" 2> "$TMP/d.txt" || true
  grep -q "SCHED_FIFO" "$TMP/d.txt" || echo "loop_jitter: WARNING: daemon ran without SCHED_FIFO" >&2
  sed -n 's/.*wake-up latency p50 \([0-9]*\) us, p99 \([0-9]*\) us, p99.9 \([0-9]*\) us, max \([0-9]*\) us.*/\1 \2 \3 \4/p' "$TMP/d.txt"
}

printf "%-6s %-10s %8s %8s %8s %8s\n" load source p50_us p99_us p99.9_us max_us
for load in idle stress; do
  if [ $load = stress ]; then stress-ng --cpu "$(nproc)" --timeout $((SECONDS_EACH + 10))s >/dev/null 2>&1 & sleep 1; fi
  # Both at once, so the host's noise over time is the same for both.
  cyclic_stats > "$TMP/c.txt" &
  cyclic_pid=$!
  daemon_stats > "$TMP/dd.txt"
  wait "$cyclic_pid"
  read -r c50 c99 c999 cmax < "$TMP/c.txt"
  read -r d50 d99 d999 dmax < "$TMP/dd.txt"
  printf "%-6s %-10s %8s %8s %8s %8s\n" $load cyclictest "$c50" "$c99" "$c999" "$cmax"
  printf "%-6s %-10s %8s %8s %8s %8s\n" $load pvcgeld "$d50" "$d99" "$d999" "$dmax"
  awk -v a="$d999" -v b="$c999" -v c="$dmax" -v d="$cmax" -v l=$load 'BEGIN {
    printf "%-6s ratio      p99.9 %.2f (target <= 1.25)   max %.2f (target <= 2)\n", l, a / (b > 0 ? b : 1), c / (d > 0 ? d : 1) }'
  if [ $load = stress ]; then pkill -f "stress-ng --cpu" 2>/dev/null || true; wait 2>/dev/null || true; fi
done
