#!/usr/bin/env bash
# Headless screenshot of the pathrl-view recording -> docs/view_demo.png
#
#   tools/view_demo.sh [EPISODES_MCAP] [OUT_PNG]
#
# Input: the given episodes.mcap, else the newest runs/*/episodes.mcap, else a synthetic iiwa7 file
# (pathrl.viz.synthetic). Shows the 3 worst episodes by cart_pos_dev_mean_cm; the viewer opens at the end of
# the `time` timeline (last episode complete). Needs Mesa's Vulkan driver and Xvfb (installed here if missing
# and run as root): Rerun's GL backend cannot render headless (notes/libraries.md section 4).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PY:-.venv/bin/python}
RERUN=${RERUN:-$(dirname "$PY")/rerun}
OUT=${2:-docs/view_demo.png}
SIZE=${SIZE:-1400x850}

if ! command -v xvfb-run >/dev/null || ! dpkg -s mesa-vulkan-drivers >/dev/null 2>&1; then
    if [ "$(id -u)" = 0 ]; then
        apt-get install -y -q mesa-vulkan-drivers xvfb >/dev/null \
            || { apt-get update -q >/dev/null && apt-get install -y -q mesa-vulkan-drivers xvfb >/dev/null; }
    else
        echo "error: need mesa-vulkan-drivers and xvfb: sudo apt-get install -y mesa-vulkan-drivers xvfb" >&2
        exit 2
    fi
fi

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
SRC=${1:-$(ls -t runs/*/episodes.mcap 2>/dev/null | head -n 1 || true)}
if [ -z "$SRC" ]; then
    SRC=$TMP/episodes.mcap
    "$PY" -c "from pathrl.viz.synthetic import write_synthetic_episodes as w; w('$SRC', 'iiwa7', episodes=12)"
fi
echo "input: $SRC"
"$PY" -m pathrl.cli.view "$SRC" --worst 3 --save "$TMP/demo.rrd"

mkdir -p "$(dirname "$OUT")"
# The X screen is much larger than the window so that the pointer (at the screen centre) is not over the
# viewer (no hover tooltip); RUST_LOG=error keeps the viewer's warnings (software rasterizer, container)
# from showing up as notification toasts in the picture; --port auto avoids clashing with a running viewer.
RUST_LOG=error xvfb-run -a -s "-screen 0 4000x3000x24" \
    "$RERUN" "$TMP/demo.rrd" --port auto --screenshot-to "$OUT" --window-size "$SIZE" >"$TMP/viewer.log" 2>&1 \
    || { tail -n 20 "$TMP/viewer.log" >&2; exit 1; }
echo "wrote $OUT"
