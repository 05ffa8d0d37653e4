#!/usr/bin/env bash
# Records a real arm run and has the native Rerun viewer (same version as the SDK,
# 0.36.3) open it under Xvfb and save a screenshot: docs/img/rerun_arm.png.
#
# Needs: the viewer (`pip install rerun-sdk==0.36.3`) and, on a machine without a
# display or GPU, Xvfb and Mesa's software Vulkan/GL drivers:
#   apt-get install xvfb mesa-vulkan-drivers libgl1-mesa-dri libxkbcommon-x11-0
# Usage: tools/rerun_screenshot.sh [SCENARIO] [OUT.png]
# (LONGREACH=path/to/longreach uses an already built binary instead of cargo run.)
set -euo pipefail
cd "$(dirname "$0")/.."

scenario=${1:-scenarios/arm_dyneema2_distal_step.toml}
png=${2:-docs/img/rerun_arm.png}
work=target/screenshot
mkdir -p "$work" "$(dirname "$png")"

if ! command -v rerun >/dev/null; then
    echo "no \`rerun\` viewer on PATH: pip install rerun-sdk==0.36.3" >&2
    exit 1
fi
if ! command -v xvfb-run >/dev/null && [ -z "${DISPLAY:-}" ]; then
    echo "no display and no xvfb-run: apt-get install xvfb mesa-vulkan-drivers libgl1-mesa-dri" >&2
    exit 1
fi

${LONGREACH:-cargo run --release --quiet --} run "$scenario" --rerun "save:$work/arm.rrd" --rerun-hz 60

# Software rendering: Mesa's lavapipe (Vulkan) or llvmpipe (GL) stand in for a GPU.
export LIBGL_ALWAYS_SOFTWARE=1
export WGPU_BACKEND=${WGPU_BACKEND:-vulkan}
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
# --screenshot-to renders the first frames, saves the PNG and quits.
viewer=(timeout 180 rerun --window-size 1600x900 --screenshot-to "$png" "$work/arm.rrd")
if [ -n "${DISPLAY:-}" ]; then
    "${viewer[@]}"
else
    xvfb-run -a -s "-screen 0 1600x900x24" "${viewer[@]}" || true
fi
if [ ! -s "$png" ]; then
    echo "the viewer wrote no screenshot: with no GPU it needs Mesa's software Vulkan (lavapipe) or GL;" >&2
    echo "try WGPU_BACKEND=gl $0, or open $work/arm.rrd on a machine with a display" >&2
    exit 1
fi
echo "wrote $png"
