#!/usr/bin/env bash
# Screenshots of every tab of `sfr lab --simulate` at 1280x800 under a real X server (Xvfb + openbox), during a
# simulated run, for docs/gui.md. Re-run from the repository root:
#
#   tools/gui_screenshots.sh [OUT_DIR]        (default docs/figures/gui)
#
# Needs: xvfb openbox xdotool imagemagick and the Qt xcb libraries (the README names them), e.g.
#   sudo apt-get install -y xvfb xdotool imagemagick openbox libxcb-cursor0 libxkbcommon-x11-0 libxcb-icccm4 \
#        libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxcb-xinerama0 libxcb-randr0 libxcb-shape0 libxcb-xkb1
# Clicks use the window's keyboard shortcuts (Bench and View menus) where there is one, else screen positions of
# the 1280x800 layout (the dock's tabs, the design form), listed below.
set -euo pipefail

OUT=${1:-docs/figures/gui}
DISPLAY_NUM=${DISPLAY_NUM:-99}
SPEED=${SPEED:-25}               # 4 h in under 10 min: every screenshot falls during the run
PY=${PY:-.venv/bin/python}
SFR=${SFR:-.venv/bin/sfr}
WORK=$(mktemp -d)
mkdir -p "$OUT"

for tool in Xvfb openbox xdotool import; do
    command -v "$tool" >/dev/null || { echo "gui_screenshots: $tool is missing (see the header of $0)" >&2; exit 2; }
done

# positions on the 1280x800 screen (openbox title bar included)
DOCK_RUN_TAB="96 68"
DOCK_CAL_TAB="164 68"
DOCK_DEV_TAB="37 68"
RUNS_FIRST_ROW="600 95"
DESIGN_TARGET="740 79"
DESIGN_RESOLUTION="740 136"
DESIGN_MAX_ITER="890 136"
DESIGN_CHECK="468 189"
DESIGN_START="560 189"
DESIGN_SWEEP_TAB="518 248"
DESIGN_DESIGN_TAB="454 248"

cleanup() {
    [[ -n ${LAB:-} ]] && kill "$LAB" 2>/dev/null || true
    [[ -n ${WM:-} ]] && kill "$WM" 2>/dev/null || true
    [[ -n ${XVFB:-} ]] && kill "$XVFB" 2>/dev/null || true
    rm -rf "$WORK"
}
trap cleanup EXIT

Xvfb ":$DISPLAY_NUM" -screen 0 1280x800x24 -nolisten tcp >"$WORK/xvfb.log" 2>&1 &
XVFB=$!
export DISPLAY=":$DISPLAY_NUM"
sleep 1
openbox >"$WORK/openbox.log" 2>&1 &
WM=$!
sleep 1

export SFR_OPERATOR="demo (simulated bench)"      # the simulated bench's built-in operator
export SFR_LAB_SETTINGS="$WORK/sfr-lab.ini"      # a fresh settings file: the defaults, not this account's
unset QT_QPA_PLATFORM

echo "simulated calibration series ..."
CAL=$("$PY" -c "from labapp.jobs.demo import simulated_calibration; print(simulated_calibration('$WORK/cal')[1])")

shot() {   # shot NAME: the whole screen
    sleep "${2:-1}"
    import -window root "$OUT/$1.png"
    echo "  $OUT/$1.png"
}
click() { xdotool mousemove $1 $2 click 1; sleep 0.5; }
key() { xdotool key "$@"; sleep 0.5; }      # to the focused window, as typed

"$SFR" lab --simulate --speed "$SPEED" --data "$WORK/data" --calibration "$CAL" >"$WORK/lab.log" 2>&1 &
LAB=$!
WIN=$(xdotool search --sync --name "Shape from Release" | head -1)
xdotool windowactivate --sync "$WIN" 2>/dev/null || true
sleep 3
click 640 9                        # the title bar: the window has the keyboard focus

echo "connect"
key F5                            # the first Connect computes the sample's dissolution: tens of seconds
shot 01_devices_connecting 2
shot 02_devices_connected 45

echo "start a run"
click $DOCK_RUN_TAB
key F6
shot 03_run_heating 15
for _ in $(seq 1 40); do          # the bath is stable when "Object dropped" is enabled: press it until it is
    key F7
    sleep 2
done
shot 04_live_run 20

click $DOCK_CAL_TAB
shot 05_calibration_tab
click $DOCK_DEV_TAB

key ctrl+2
click $RUNS_FIRST_ROW
shot 06_runs 3

key ctrl+3
click $DESIGN_TARGET
xdotool type --delay 20 "accel:q=2"
click $DESIGN_RESOLUTION
key ctrl+a
xdotool type "32"
click $DESIGN_MAX_ITER
key ctrl+a
xdotool type "200"
click $DESIGN_CHECK
shot 07_design_target_checked 8
click $DESIGN_START
shot 08_design_running 40
click $DESIGN_SWEEP_TAB
shot 09_design_sweep
click $DESIGN_DESIGN_TAB

key ctrl+1
shot 10_live_later 5

echo "quit while the run goes on: the window asks, Escape keeps it running; SIGTERM stops it as closing does"
key ctrl+q
shot 11_quit_asks 2
key Escape
kill -TERM "$LAB"
shot 12_stopping 1
for _ in $(seq 1 60); do kill -0 "$LAB" 2>/dev/null || break; sleep 1; done
echo "done: $(ls "$OUT" | wc -l) screenshots in $OUT"
