#!/bin/bash
# Issue 14, item 3: one chain, end to end, with the tools a user has (never the truth's parameters):
#   record with pvcgeld -> pvcgel diagnose -> pvcgeld with the augmented model -> track the paper's references.
# Run on three simulated rigs whose truth is the paper's model (Table II n = 3, eq. (11)) plus effects the
# nominal model (that same paper model) lacks, and prints mean |e| of inverse_pid_dob_ff with the diagnosed
# model, without the effects (the nominal model), and the noise floor, with the ratios.
#
# Usage: benchmarks/effect_chain.sh [--build DIR] [--out DIR] [--rigs "hysteresis creep both"]
#                                   [--modes "inverse_pid_dob_ff inverse_pid_dob"] [--track-s S] [--settle-s S] [--jobs N] [--plot PNG]
# The benchmark: the defaults (60 s per reference, mean |e| over 20..60 s as `pvcgel bench paper`).
# The e2e test (ctest EffectChainE2E) runs it shorter and checks results.tsv and diagnosis.tsv.
# pvcgeld runs in real time (no accelerated mode): two 40 s recordings per rig, then --track-s per reference;
# runs go in parallel (--jobs, default 8; a sim pvcgeld needs a few % of a core). DDS is off in every run.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=$ROOT/build OUT=$ROOT/out/effect_chain RIGS="hysteresis creep both" MODES=inverse_pid_dob_ff TRACK_S=60 SETTLE_S=20 JOBS=8 PLOT=""
while [ $# -gt 0 ]; do
  case $1 in
    --build) BUILD=$2; shift 2 ;;
    --out) OUT=$2; shift 2 ;;
    --rigs) RIGS=$2; shift 2 ;;
    --modes) MODES=$2; shift 2 ;;
    --track-s) TRACK_S=$2; shift 2 ;;
    --settle-s) SETTLE_S=$2; shift 2 ;;
    --jobs) JOBS=$2; shift 2 ;;
    --plot) PLOT=$2; shift 2 ;;
    *) echo "effect_chain: unknown argument '$1' (see the usage at the top of $0)" >&2; exit 64 ;;
  esac
done
PVCGELD=$BUILD/daemon/pvcgeld PVCGEL=$BUILD/tools/pvcgel
for b in "$PVCGELD" "$PVCGEL"; do [ -x "$b" ] || { echo "effect_chain: $b not built" >&2; exit 1; }; done
mkdir -p "$OUT"
REFERENCES="0.1hz 0.5hz 1hz multi"
RECORD_S=40

# ------------------------------------------------------------------ configuration files
# FILE without the listed tables (a table's body ends at the next [header]).
toml_without() {
  awk -v drop=" $2 " '/^\[/ { name = $0; gsub(/^\[+|\]+.*$/, "", name); skip = index(drop, " " name " ") > 0 } !skip' "$1"
}
# Only the listed tables of FILE (with [[array]] tables), in file order.
toml_only() {
  awk -v keep=" $2 " '/^\[/ { name = $0; gsub(/^\[+|\]+.*$/, "", name); on = index(keep, " " name " ") > 0 } on' "$1"
}
# The rigs' added effects. Hysteresis "at 5% of the peak-to-peak stroke": the quasi-static loop of the truth
# driven between the voltages that give the paper's y_r1 range (75..125 um, 315..380 V) is at most 2.3 um
# wide, 5.0% of its 46 um peak-to-peak (Prandtl-Ishlinskii, control/effect.hpp: alpha 0.205 with plays up to
# 2.08 x 15 V; the width grows about linearly with alpha). Creep at 5% with a 10 s time constant: a
# Kelvin-Voigt branch 0.05 G(0) / (10 s + 1) in parallel with G (a step settles 5% further, tau 10 s).
effect_tables() {
  local hyst='[[sim.truth.effect]]
name = "hysteresis"
alpha = 0.205
threshold_scale_V = 15.0'
  local creep='[[sim.truth.effect]]
name = "creep"
fraction = 0.05
time_constant_s = 10.0'
  case $1 in
    hysteresis) echo "$hyst" ;;
    creep) echo "$creep" ;;
    both) printf '%s\n%s\n' "$hyst" "$creep" ;;
    floor) ;;  # truth = the model: the noise floor
    *) echo "effect_chain: unknown rig '$1' (hysteresis, creep, both)" >&2; exit 64 ;;
  esac
}
# The rig's configuration: the shipped sim config with its truth (the paper's model, Table II n = 3) as the
# rig's nominal [model] (the paper's identified model, exact for this truth without its effects), so the
# added effects are all the model lacks; the controller stays 2% below f's turnover at 862 V, as ident
# writes it. The built-in Bouc-Wen hysteresis and creep are off, the rig's effects are added to the truth;
# DDS is off (no participant is needed); overruns never fault (the sim's time is the cycle count, so a late
# cycle on this shared machine changes nothing but would stop the run). "floor": the truth equals the model.
rig_config() {
  local rig=$1
  toml_without "$ROOT/config/pvcgeld-sim.toml" "model sim.hysteresis sim.creep dds run" |
    sed -e 's/^overrun_fault_after = .*/overrun_fault_after = 0/' -e 's/^voltage_max_V = .*/voltage_max_V = 845.0/'
  echo
  toml_only "$ROOT/config/pvcgeld-sim.toml" "sim.truth" | sed -e 's/^\[sim.truth\].*/[model]/'
  printf 'io_delay_samples = 1\n\n[sim.hysteresis]\nenabled = false\n\n[sim.creep]\nenabled = false\n\n[dds]\nenabled = false\n\n'
  effect_tables "$rig"
}
# MODE in a configuration ([controller] mode is the file's only `mode =` key).
with_mode() { sed -e "s/^mode = .*/mode = \"$2\"/" "$1"; }

# ------------------------------------------------------------------ running pvcgeld, in parallel
running=0
throttle() { if [ "$running" -ge "$JOBS" ]; then wait -n || true; running=$((running - 1)); fi; running=$((running + 1)); }
# pvcgeld CONFIG TRAJECTORY SECONDS RECORDING: the log beside the recording; never stops the script.
run_daemon() {
  "$PVCGELD" --config "$1" --trajectory "$2" --duration "$3" --record "$4" > "${4%.csv}.log" 2>&1 || true
}

# What is recorded on each rig, closed loop under the rig's shipped controller (inverse_pid_dob), two
# recordings of RECORD_S s: the paper's multi-harmonic y_r2 (reversals at three frequencies: hysteresis loops,
# rate dependence) and steps with holds at 125, 75 and 100 um (creep: the voltage keeps moving for tens of
# seconds after each step), joined by 1 s ramps (t_s,r_um every 10 ms). Diagnosed together.
steps_csv() {
  awk 'function ramp(t, t0, a, b) { return a + (b - a) * (t - t0) }
       BEGIN { print "t_s,r_um";
         for (k = 0; k <= 4000; k++) { t = k / 100.0;
           if (t < 2) r = 100; else if (t < 3) r = ramp(t, 2, 100, 125); else if (t < 15) r = 125;
           else if (t < 16) r = ramp(t, 15, 125, 75); else if (t < 28) r = 75;
           else if (t < 29) r = ramp(t, 28, 75, 100); else r = 100;
           printf "%.2f,%.4f\n", t, r } }'
}

# ------------------------------------------------------------------ the chain
steps_csv > "$OUT/steps.csv"
rig_config floor > "$OUT/floor.toml"
echo "effect_chain: 1/3 recording 2 x ${RECORD_S} s on each rig ($RIGS) with pvcgeld" >&2
for rig in $RIGS; do
  mkdir -p "$OUT/$rig"
  rig_config "$rig" > "$OUT/$rig/rig.toml"
  throttle; run_daemon "$OUT/$rig/rig.toml" paper-multi $RECORD_S "$OUT/$rig/recording-multi.csv" &
  throttle; run_daemon "$OUT/$rig/rig.toml" "csv:$OUT/steps.csv" $RECORD_S "$OUT/$rig/recording-steps.csv" &
done
wait; running=0

echo "effect_chain: 2/3 pvcgel diagnose --model rig.toml recording-multi.csv recording-steps.csv" >&2
diagnose_rig() {
  local d=$OUT/$1
  # The user's model is the one the rig's configuration ships; diagnose keeps its other tables and writes
  # [model] + [[model.effect]] (for the controller) and [sim] (its estimate of the rig) to augmented.toml.
  "$PVCGEL" diagnose --model "$d/rig.toml" --json "$d/diagnosis.json" --out "$d/augmented.toml" \
    "$d/recording-multi.csv" "$d/recording-steps.csv" > "$d/diagnose.txt" 2>&1 || echo "effect_chain: diagnose failed on $1 (see $d/diagnose.txt)" >&2
  # The rig itself (its [sim] is the truth, never diagnose's estimate of it) with the augmented [model].
  { toml_without "$d/rig.toml" "model"; echo; toml_only "$d/augmented.toml" "model model.effect"; } > "$d/augmented-rig.toml"
}
for rig in $RIGS; do throttle; diagnose_rig "$rig" & done
wait; running=0

echo "effect_chain: 3/3 tracking the paper's references in $MODES, ${TRACK_S} s each" >&2
for mode in $MODES; do
  # Written once per mode, before any run starts: rewriting them per reference truncated a file that a run
  # started in the background for the previous reference might not have read yet ("is empty", 1 run in ~20).
  with_mode "$OUT/floor.toml" "$mode" > "$OUT/floor-$mode.toml"
  for rig in $RIGS; do
    with_mode "$OUT/$rig/rig.toml" "$mode" > "$OUT/$rig/nominal-$mode.toml"
    with_mode "$OUT/$rig/augmented-rig.toml" "$mode" > "$OUT/$rig/augmented-$mode.toml"
  done
  for ref in $REFERENCES; do
    throttle; run_daemon "$OUT/floor-$mode.toml" "paper-$ref" "$TRACK_S" "$OUT/floor-$mode-$ref.csv" &
    for rig in $RIGS; do
      d=$OUT/$rig
      for model in nominal augmented; do
        throttle; run_daemon "$d/$model-$mode.toml" "paper-$ref" "$TRACK_S" "$d/track-$model-$mode-$ref.csv" &
      done
    done
  done
done
wait; running=0

# ------------------------------------------------------------------ results
# mean |e| over RUNNING rows from SETTLE_S on; "n/a" when the run did not reach them (the log says why).
mean_abs_e() {
  [ -s "$1" ] || { echo n/a; return; }
  awk -F, -v settle="$SETTLE_S" '/^#/ || /^t_s/ { next } $1 >= settle && $8 == "RUNNING" { s += ($5 < 0 ? -$5 : $5); n++ }
    END { if (n > 0) printf "%.4f\n", s / n; else print "n/a" }' "$1"
}
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (a == "n/a" || b == "n/a" || b + 0 <= 0) print "n/a"; else printf "%.2f\n", a / b }'; }
json_string() { grep -o "\"$2\": \"[^\"]*\"" "$1" 2>/dev/null | head -1 | sed 's/.*: "\(.*\)"/\1/' || true; }
mixture_names() {
  grep -o '"mixture": \[[^]]*\]' "$1" 2>/dev/null | grep -o '"name": "[a-z_]*"' | sed 's/.*: "\(.*\)"/\1/' | paste -sd+ - || true
}
printf 'mode\trig\treference\tdiagnosed_um\tnominal_um\tfloor_um\n' > "$OUT/results.tsv"
printf 'rig\tverdict\tmixture\n' > "$OUT/diagnosis.tsv"
for rig in $RIGS; do
  verdict=$(json_string "$OUT/$rig/diagnosis.json" verdict); mixture=$(mixture_names "$OUT/$rig/diagnosis.json")
  printf '%s\t%s\t%s\n' "$rig" "${verdict:-failed}" "${mixture:--}" >> "$OUT/diagnosis.tsv"
done
noise_sigma=$(awk -F= '/^noise_sigma_um/ { print $2 + 0 }' "$ROOT/config/pvcgeld-sim.toml")
echo
echo "Noise floor: the same controller on a rig whose truth equals the model (same sensor noise);"
echo "the sensor noise alone has mean |n| = $(awk -v s="$noise_sigma" 'BEGIN { printf "%.4f", s * sqrt(2 / atan2(0, -1)) }') um."
echo "mean |e| in um from ${SETTLE_S} s to the end of each ${TRACK_S} s run; ratios: diagnosed / floor (target <= 1.5"
echo "for inverse_pid_dob_ff) and without / diagnosed (> 1: the diagnosed model tracks better)."
for mode in $MODES; do
  echo; echo "$mode:"; echo
  printf '| rig | diagnosis | reference | diagnosed model | without the effects | noise floor | diagnosed / floor | without / diagnosed |\n'
  printf '| --- | --- | --- | --- | --- | --- | --- | --- |\n'
  while IFS=$'\t' read -r rig verdict mixture; do
    [ "$rig" = rig ] && continue
    for ref in $REFERENCES; do
      d=$OUT/$rig
      aug=$(mean_abs_e "$d/track-augmented-$mode-$ref.csv"); nom=$(mean_abs_e "$d/track-nominal-$mode-$ref.csv")
      floor=$(mean_abs_e "$OUT/floor-$mode-$ref.csv")
      printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$mode" "$rig" "$ref" "$aug" "$nom" "$floor" >> "$OUT/results.tsv"
      printf '| %s | %s | %s | %s | %s | %s | %s | %s |\n' "$rig" "$([ "$mixture" = - ] && echo "$verdict" || echo "$mixture")" \
        "$ref" "$aug" "$nom" "$floor" "$(ratio "$aug" "$floor")" "$(ratio "$nom" "$aug")"
    done
  done < "$OUT/diagnosis.tsv"
done
# Say why runs are missing or faulted (their logs have pvcgeld's reason): each reason once, with a count.
for log in "$OUT"/*/track-*.log "$OUT"/floor-*.log "$OUT"/*/recording-*.log; do
  if grep -q "configuration error\|fault: [a-z]" "$log" && ! grep -q "fault: none" "$log"; then
    # A configuration error without a key's "(in" (an empty file) is said up to its first ';': a grep that
    # matched nothing here ended the whole script (set -e, pipefail) with exit 1 and no reason given.
    { grep -m1 -o "configuration error.*(in\|fault: [a-z_]*" "$log" || grep -m1 -o "configuration error[^;]*" "$log" || true; } |
      sed 's/ (in$//'
  fi
done | sort | uniq -c | while read -r count reason; do echo; echo "NOTE: $count runs: pvcgeld: $reason"; done
# ------------------------------------------------------------------ plot: tracking error before and after
# The first mode, the paper's 1 Hz reference (where the effects show most), 5 s after the settling time.
PLOT_MODE=${MODES%% *}
if [ -n "$PLOT" ] && [ "$(mean_abs_e "$OUT/${RIGS%% *}/track-augmented-$PLOT_MODE-1hz.csv")" = n/a ]; then
  echo "effect_chain: no plot: the augmented runs did not happen" >&2
elif [ -n "$PLOT" ]; then
  plot_data=$OUT/plot.dat
  : > "$plot_data"
  # e averaged over 20 ms (centred): the sensor noise (mean |n| 0.04 um) would hide the effects' systematic error.
  smoothed_error() {
    awk -F, -v settle="$SETTLE_S" '/^#/ || /^t_s/ { next } $1 >= settle - 0.01 && $1 < settle + 5.01 && $8 == "RUNNING" {
        t[n] = $1; e[n] = $5; n++ }
      END { for (i = 10; i < n - 10; i++) { s = 0; for (j = -10; j < 10; j++) s += e[i + j]; print t[i] - settle, s / 20 } }' "$1"
  }
  for rig in $RIGS; do
    for file in "$OUT/$rig/track-nominal-$PLOT_MODE-1hz.csv" "$OUT/$rig/track-augmented-$PLOT_MODE-1hz.csv" \
                "$OUT/floor-$PLOT_MODE-1hz.csv"; do
      smoothed_error "$file" >> "$plot_data"
      printf '\n\n' >> "$plot_data"
    done
  done
  n_rigs=$(echo $RIGS | wc -w)
  {
    echo "set terminal pngcairo size 1100,$((250 * n_rigs + 40)) font ',10'; set output '$PLOT'"
    echo "set multiplot layout $n_rigs,1 title \"$PLOT_MODE tracking the paper's y_r1 at 1 Hz: error (20 ms mean) without and with the diagnosed effects\" noenhanced"
    echo "set xlabel 't - ${SETTLE_S} s (s)'; set ylabel 'e = r - y, 20 ms mean (um)'; set grid; set key below horizontal"
    i=0
    for rig in $RIGS; do
      echo "set title \"truth: paper model + $rig\" noenhanced"
      echo "plot '$plot_data' index $((3 * i + 2)) using 1:2 with lines lw 1 lc rgb '#999999' title 'noise floor rig (truth = model)', '' index $((3 * i)) using 1:2 with lines lw 2 lc rgb '#d95f02' title 'without the effects (nominal [model])', '' index $((3 * i + 1)) using 1:2 with lines lw 2 lc rgb '#1b9e77' title 'diagnosed model ([model] + [[model.effect]])'"
      i=$((i + 1))
    done
    echo "unset multiplot"
  } > "$OUT/plot.gp"
  gnuplot "$OUT/plot.gp" && echo "effect_chain: plot $PLOT" >&2
fi
