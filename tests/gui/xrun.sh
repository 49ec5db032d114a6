#!/usr/bin/env bash
# Inside tools/guiroot: one real Blender window on its own virtual X server.
#   xrun.sh OUT SCENARIO ZIP [TIMEOUT_S]
# Xvfb picks a free display number itself (-displayfd), so concurrent runs never share one; HOME is a
# fresh folder (a clean user configuration, the extension installed into it); Blender runs the driver,
# which steps SCENARIO and writes OUT/result.json. Blender's output goes to OUT/blender.log.
set -u
OUT=$1 SCENARIO=$2 ZIP=$3 LIMIT=${4:-300}
HERE="$(cd "$(dirname "$0")" && pwd)"
mkdir -p "$OUT"
export HOME; HOME=$(mktemp -d /tmp/gui-home.XXXXXX)
fifo=$(mktemp -u /tmp/gui-display.XXXXXX); mkfifo "$fifo"
Xvfb -displayfd 5 -screen 0 1600x1000x24 -nolisten tcp 5>"$fifo" >"$OUT/xvfb.log" 2>&1 &
xpid=$!
read -r -t 30 display <"$fifo" || { echo "xrun: Xvfb did not start"; cat "$OUT/xvfb.log"; kill $xpid 2>/dev/null; exit 3; }
rm -f "$fifo"
export DISPLAY=":$display"
echo "xrun: display $DISPLAY, HOME $HOME"
# Blender opens its window over the whole screen (no window manager: the pointer gives the focus).
timeout -k 10 "$LIMIT" blender --factory-startup --window-geometry 0 0 1600 1000 --no-window-focus \
    --python "$HERE/driver.py" -- "$OUT" "$SCENARIO" "$ZIP" >"$OUT/blender.log" 2>&1
rc=$?
kill $xpid 2>/dev/null; wait $xpid 2>/dev/null
rm -rf "$HOME"
exit $rc
