#!/usr/bin/env bash
# Screenshots of every tab of `sfr lab --simulate` at 1280x800 under a real X server (Xvfb + openbox), during a
# simulated run, for docs/gui.md. Re-run from the repository root:
#
#   tools/gui_screenshots.sh [OUT_DIR] [all|tour|faults]     (default docs/figures/gui all)
#
# "tour" takes the tabs during one run (01-12); "faults" rehearses the faults from the window's Simulated bench
# menu (13-19): the heating, stale readouts and a lost hotplate link, the link back, a second run before its drop,
# and a run resumed after SIGTERM.
#
# Needs: xvfb openbox xdotool imagemagick and the Qt xcb libraries (the README names them), e.g.
#   sudo apt-get install -y xvfb xdotool imagemagick openbox libxcb-cursor0 libxkbcommon-x11-0 libxcb-icccm4 \
#        libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxcb-xinerama0 libxcb-randr0 libxcb-shape0 libxcb-xkb1
# Clicks use the window's keyboard shortcuts (Bench and View menus) where there is one, else screen positions of
# the 1280x800 layout (the dock's tabs, the design form), listed below.
set -euo pipefail

OUT=${1:-docs/figures/gui}
WHAT=${2:-all}
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
DESIGN_MAX_ITER="975 136"
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

start_lab() {   # start_lab LOG [OPTIONS...]: the window, focused
    local log=$1
    shift
    "$SFR" lab --simulate --speed "$SPEED" --data "${DATA:-$WORK/data}" "$@" >"$log" 2>&1 &
    LAB=$!
    WIN=$(xdotool search --sync --name "Shape from Release" | head -1)
    xdotool windowactivate --sync "$WIN" 2>/dev/null || true
    sleep 3
    click 640 9                    # the title bar: the window has the keyboard focus
}

stop_lab() {    # SIGTERM, as a service manager stops it: the run is interrupted, resumable
    kill -TERM "$LAB"
    for _ in $(seq 1 60); do kill -0 "$LAB" 2>/dev/null || break; sleep 1; done
}

drop_when_stable() {   # press Object dropped (F7) until the bath is stable and it is enabled
    for _ in $(seq 1 "${1:-40}"); do
        key F7
        sleep 2
    done
}

faults() {
    DATA=$WORK/rehearsal           # a data folder of its own: nothing interrupted to offer at the start
    # a short rehearsal run: 40 C (heats in seconds at x25), 30 s frames, 1 h (under two and a half minutes at x25)
    SFR_LAB_SETTINGS="$SFR_LAB_SETTINGS" "$PY" -c "
from labapp.acquisition.procedures import RunConfig
from labapp.acquisition.settings import BathSettings
from labapp.gui import persist
config = RunConfig(name='rehearsal', interval_s=30, max_duration_s=3600, stop_on_steady=False,
                   bath=BathSettings(setpoint_c=40.0, tolerance_c=1.0, hold_s=60.0))
persist.remember_run(persist.app_settings(), config, '$CAL')"
    start_lab "$WORK/faults.log"
    echo "faults: connect, start, the heating"
    key F5
    sleep 45
    click $DOCK_RUN_TAB
    key F6
    shot 13_run_heating_visible 8
    drop_when_stable 8
    sleep 15
    echo "faults: the hotplate link drops (Simulated bench > Drop the hotplate link)"
    key ctrl+shift+l
    shot 14_stale_readouts 4
    shot 15_link_lost 25
    echo "faults: the link comes back"
    key ctrl+shift+r
    shot 16_link_back 8
    echo "faults: a second run, before its drop"
    sleep 95                       # the first run ends at 1 h (144 s at x25)
    click $DOCK_RUN_TAB
    key F6
    shot 17_second_run_before_drop 35
    key F7
    sleep 20
    echo "faults: SIGTERM, then the window again: it offers to resume"
    stop_lab
    start_lab "$WORK/resumed.log"
    key Return                     # "Resume newest"
    shot 18_resumed_run 15
    click $DOCK_RUN_TAB
    shot 19_resumed_run_tab 2
    stop_lab
}

if [[ $WHAT == faults ]]; then
    faults
    echo "done: $(ls "$OUT" | wc -l) screenshots in $OUT"
    exit 0
fi

start_lab "$WORK/lab.log" --calibration "$CAL"

echo "connect"
key F5                            # the first Connect computes the sample's dissolution: tens of seconds
shot 01_devices_connecting 2
shot 02_devices_connected 45

echo "start a run"
click $DOCK_RUN_TAB
key F6
shot 03_run_heating 15
drop_when_stable 40               # the bath is stable when "Object dropped" is enabled: press it until it is
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
[[ $WHAT == all ]] && faults
echo "done: $(ls "$OUT" | wc -l) screenshots in $OUT"
