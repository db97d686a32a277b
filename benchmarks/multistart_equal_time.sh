#!/usr/bin/env bash
# One start against `--starts 4` at equal wall time (docs/design.md#multi-start).
#
#   bash benchmarks/multistart_equal_time.sh SOURCE OUT_DIR [RESOLUTION] [SPACE]
#
# Runs `sfr design --target SOURCE --space SPACE --resolution R` (default 128, extruded) three times
# into OUT_DIR: one start with 300 evaluations (wall time T_1), `--starts 4 --max-iter 300` (wall time
# T_4, outputs included), and one start with 300 T_4 / T_1 evaluations (rounded to 10, at least 300).
# Runs whose folder holds a summary are kept, so an interrupted sweep resumes (their times are then
# those of this call: 0 s).
# Prints one markdown row: binary rel. RMSE / pieces of each, the two times and the evaluations given.
set -euo pipefail
source=$1
out=$2
resolution=${3:-128}
space=${4:-extruded}
python=${PYTHON:-python}
design() { "$python" -m labapp.cli.main design --target "$source" --space "$space" --resolution "$resolution" "$@"; }
now() { "$python" -c 'import time; print(time.time())'; }
timed() {  # timed FOLDER ARGS...: run into FOLDER unless done; prints the wall seconds
    local folder=$1 start
    shift
    start=$(now)
    [ -e "$folder/summary.json" ] || design "$@" --out "$folder" > "$folder.log" 2>&1
    "$python" -c "import time; print(time.time() - $start)"
}
mkdir -p "$out"
t1=$(timed "$out/single" --max-iter 300 --starts 1)
t4=$(timed "$out/multi" --max-iter 300 --starts 4)
evals=$("$python" -c "print(max(300, int(round(300 * $t4 / max($t1, 1e-9) / 10.0)) * 10))")
timed "$out/equal" --max-iter "$evals" --starts 1 > /dev/null
"$python" - "$out" "$(basename "$source")" "$t1" "$t4" "$evals" <<'PY'
import json, sys
out, name, t1, t4, evals = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), sys.argv[5]
fit = {}
for run in ("single", "multi", "equal"):
    s = json.load(open(f"{out}/{run}/summary.json"))
    fit[run] = f"{s['rel_rmse_binary']:.2%} / {s['pieces']}"
print(f"| {name} | {fit['single']} | {fit['multi']} ({t4:.0f} s vs {t1:.0f} s) | {fit['equal']} ({evals}) |")
PY
