#!/usr/bin/env bash
# The identification figures of docs/identification.md: every real record of
# the repository and the lab-like records, with the defaults, seeds 0, 1, 2,
# fit part / scored part. Prints one markdown row per record, model and seed
# (unseen RMS as % of the fit part's span, the baselines, fit time) and keeps
# every --report in out/identify/.
#
#   piezo-identify/benches/figures.sh [target/release/piezo-identify]
set -euo pipefail
B=${1:-target/release/piezo-identify}
D=piezo-identify/tests/data/piezo-p885
O=out/identify
mkdir -p "$O"
P885=(--input 0 --output 4 --rate 200)

# The lab-like records of tests/quality_bars.rs (name: lab-record options).
declare -A LAB=(
  [lab_200Hz_unipolar_1Hz]="--rate 200 --drive unipolar --frequency 1 --seconds 20"
  [lab_200Hz_bipolar_0.1Hz]="--rate 200 --drive bipolar --frequency 0.1 --seconds 40"
  [lab_5kHz_unipolar_10Hz]="--rate 5000 --drive unipolar --frequency 10 --seconds 4"
  [lab_5kHz_bipolar_1Hz]="--rate 5000 --drive bipolar --frequency 1 --seconds 6"
  [lab_200Hz_unipolar_1Hz_swept]="--rate 200 --drive unipolar --frequency 1 --seconds 30 --sweep 10"
  [lab_200Hz_unipolar_stairs]="--rate 200 --drive unipolar --stairs 0.2 --seconds 40"
  [lab_5kHz_unipolar_stairs]="--rate 5000 --drive unipolar --stairs 0.2 --seconds 40"
)
for name in "${!LAB[@]}"; do
  # shellcheck disable=SC2086
  "$B" lab-record ${LAB[$name]} --out "$O/$name.csv" > /dev/null
done

row() { # model record seed report-file part
  python3 - "$@" <<'PY'
import json, sys
model, record, seed, path, part = sys.argv[1:6]
r = json.load(open(path))
if model == "inverse-pi":
    ident = r["identification"]
    e = ident["unseen"] if part == "unseen" else r["validation"]["errors"]
    print(f"| {record} | inverse-pi | {seed} | {e['proposed']['rms_percent']:.3f} | "
          f"{e['classical']['rms_percent']:.3f} | {e['line']['rms_percent']:.3f} | | "
          f"{'rate-dependent' if ident['rate_dependent'] else 'constant'}, smooth {ident['smoothing']} | {ident['seconds']:.1f} |")
else:
    e = r["unseen"] if part == "unseen" else r["validation"]["errors"]
    print(f"| {record} | bouc-wen | {seed} | {e['bouc_wen']['rms_percent']:.3f} | "
          f"{e['classical']['rms_percent']:.3f} | {e['line']['rms_percent']:.3f} | "
          f"{e['best_line']['rms_percent']:.3f} | n {r['identification']['refined']['params']['n']:.3f}, "
          f"LM {'kept' if r['identification']['refinement_kept'] else 'not kept'} | {r['seconds']:.1f} |")
PY
}

echo "| record | model | seed | unseen RMS % | classical P-I % | line % | best line % | choices | fit s |"
echo "|---|---|---|---|---|---|---|---|---|"
for seed in 0 1 2; do
  for file in Model_Vi_Do Test_Vi_Do_Di; do
    for model in inverse-pi bouc-wen; do
      report="$O/$file.$model.seed$seed.json"
      "$B" "$model" "$D/$file.dat" "${P885[@]}" --split 0.5 --seed "$seed" --report "$report" > /dev/null 2>&1
      row "$model" "$file.dat --split 0.5" "$seed" "$report" unseen
    done
  done
  for model in inverse-pi bouc-wen; do
    report="$O/Model_Test.$model.seed$seed.json"
    "$B" "$model" "$D/Model_Vi_Do.dat" "${P885[@]}" --validate "$D/Test_Vi_Do_Di.dat" --seed "$seed" \
      --report "$report" > /dev/null 2>&1
    row "$model" "Model_Vi_Do.dat --validate Test_Vi_Do_Di.dat" "$seed" "$report" validation
  done
  for name in $(printf '%s\n' "${!LAB[@]}" | sort); do
    for model in inverse-pi bouc-wen; do
      report="$O/$name.$model.seed$seed.json"
      "$B" "$model" "$O/$name.csv" --input command_V --output displacement_um \
        --rate "$(echo "${LAB[$name]}" | awk '{print $2}')" --split 0.5 --seed "$seed" \
        --report "$report" > /dev/null 2>&1
      row "$model" "$name" "$seed" "$report" unseen
    done
  done
done
