#!/usr/bin/env bash
# Records a real arm run (or, given a Bode scenario, the rig's runs) and screenshots
# the native Rerun viewer (same version as the SDK, 0.36.3) showing it with its
# default layout: docs/img/rerun_arm.png; docs/img/rerun_bode.png came from
#   tools/rerun_screenshot.sh scenarios/bode_dyneema2.toml docs/img/rerun_bode.png
#
# Needs:
#   pip install rerun-sdk==0.36.3 pillow     # the viewer (+ its Python client) and PIL
# and, on a machine without a display or GPU, Xvfb and Mesa's software Vulkan driver
# (lavapipe); Debian 12 package names, the set it was run with on 2026-11-22:
#   apt-get install xvfb mesa-vulkan-drivers libgl1-mesa-dri libxkbcommon-x11-0
# (Mesa 22.3's software GL, llvmpipe, is not enough: with WGPU_BACKEND=gl the viewer
# exits with "Adapter does not support drawing to texture format R32Float".)
# Usage: tools/rerun_screenshot.sh [SCENARIO] [OUT.png]
# Environment: LONGREACH=path/to/longreach uses an already built binary instead of
#   cargo run; WGPU_BACKEND=vulkan|gl (default vulkan); WINDOW=1600x900 (viewer size
#   in points); SETTLE=10 (seconds the viewer gets before the screenshot);
#   PORT=19876 (the viewer's gRPC port, away from the default 9876 so a viewer you
#   have open is not used).
#
# How: the viewer opens the recording under Xvfb (or $DISPLAY), the script waits
# SETTLE seconds, then asks it for a screenshot through its gRPC API
# (rerun.experimental.ViewerClient.save_screenshot), stops it and downscales the
# image to the window size (the viewer always captures at 2 pixels per point).
# Not `rerun --screenshot-to`: that requests the 2x window before the window size is
# known, so wgpu is asked for a 20000x20000 surface ("exceeds 16384") and the error
# toast can end up in the picture.
set -euo pipefail
cd "$(dirname "$0")/.."

scenario=${1:-scenarios/arm_dyneema2_distal_step.toml}
png=${2:-docs/img/rerun_arm.png}
window=${WINDOW:-1600x900}
settle=${SETTLE:-10}
port=${PORT:-19876}
work=target/screenshot
mkdir -p "$work" "$(dirname "$png")"

die() { echo "rerun_screenshot: $*" >&2; exit 1; }

command -v rerun >/dev/null || die "no \`rerun\` viewer on PATH: pip install rerun-sdk==0.36.3"
python3 -c 'import rerun.experimental, PIL' 2>/dev/null ||
    die "python3 lacks rerun-sdk or Pillow: pip install rerun-sdk==0.36.3 pillow"
version=$(rerun --version | awk 'NR == 1 {print $2}')
[ "$version" = 0.36.3 ] || echo "rerun_screenshot: warning: viewer is $version, the SDK is 0.36.3" >&2
if [ -z "${DISPLAY:-}" ] && ! command -v xvfb-run >/dev/null; then
    die "no display and no xvfb-run: apt-get install xvfb mesa-vulkan-drivers libgl1-mesa-dri libxkbcommon-x11-0"
fi
if python3 -c "import socket,sys; sys.exit(socket.socket().connect_ex(('127.0.0.1', $port)) != 0)"; then
    die "port $port is taken (another viewer?): set PORT to a free one"
fi
# The `rerun` on PATH is a Python wrapper that starts the real binary as a child:
# run the binary itself so that stopping it by its pid stops the viewer.
viewer_bin=$(python3 -c 'import os, rerun_cli; print(os.path.join(os.path.dirname(rerun_cli.__file__), "rerun"))')
[ -x "$viewer_bin" ] || viewer_bin=$(command -v rerun)

# A Bode scenario (`kind = "bode"`) is recorded by `longreach bode`, any other by `run`.
command=run
grep -Eq '^kind *= *"bode"' "$scenario" && command=bode
${LONGREACH:-cargo run --release --quiet --} "$command" "$scenario" --rerun "save:$work/arm.rrd" --rerun-hz 60 >/dev/null

# Software rendering: Mesa's lavapipe (Vulkan) or llvmpipe (GL) stand in for a GPU.
export LIBGL_ALWAYS_SOFTWARE=1
export WGPU_BACKEND=${WGPU_BACKEND:-vulkan}
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
export VIEWER_BIN=$viewer_bin PORT=$port WINDOW=$window SETTLE=$settle
export RRD=$work/arm.rrd LOG=$work/viewer.log RAW=$work/raw.png
rm -f "$RAW"

# Runs on the (virtual) display: start the viewer, screenshot it, stop it.
session='
"$VIEWER_BIN" --port "$PORT" --window-size "$WINDOW" --hide-welcome-screen "$RRD" >"$LOG" 2>&1 &
viewer=$!
VIEWER_PID=$viewer python3 - <<"EOF"
import os, sys, time
import rerun.experimental as rre
url = "rerun+http://127.0.0.1:%s/proxy" % os.environ["PORT"]
raw = os.path.abspath(os.environ["RAW"])
def alive():
    try:
        os.kill(int(os.environ["VIEWER_PID"]), 0)
        return True
    except OSError:
        return False
for _ in range(60):
    try:
        client = rre.ViewerClient(url)
        break
    except Exception as err:
        last = err
        if not alive():
            sys.exit("the viewer exited at start-up")
        time.sleep(1)
else:
    sys.exit("no viewer answered at %s: %s" % (url, last))
time.sleep(float(os.environ["SETTLE"]))
client.save_screenshot(raw)
from PIL import Image
for _ in range(120):  # the file is there once PIL can read all of it
    time.sleep(0.5)
    try:
        Image.open(raw).load()
        break
    except Exception:
        if not alive():
            break
else:
    sys.exit("the viewer saved no screenshot to %s" % raw)
EOF
status=$?
kill "$viewer" 2>/dev/null || true
wait "$viewer" 2>/dev/null || true
exit $status'

status=0
if [ -n "${DISPLAY:-}" ]; then
    timeout 300 bash -c "$session" || status=$?
else
    w=${window%x*} h=${window#*x}
    timeout 300 xvfb-run -a -s "-screen 0 $((2 * w))x$((2 * h))x24" bash -c "$session" || status=$?
fi

if [ ! -s "$RAW" ]; then
    echo "rerun_screenshot: the viewer wrote no screenshot (exit $status). Its errors ($LOG):" >&2
    sed 's/\x1b\[[0-9;]*m//g' "$LOG" | grep -E -A4 'ERROR|panicked|adapter|No suitable' | head -40 >&2 || true
    echo "With no GPU the viewer needs Mesa's software Vulkan driver, lavapipe (apt-get install" >&2
    echo "mesa-vulkan-drivers), and WGPU_BACKEND=vulkan: Mesa 22.3's GL (llvmpipe) is not enough" >&2
    echo "(\"Adapter does not support drawing to texture format R32Float\"). Otherwise open" >&2
    echo "$RRD on a machine with a GPU and a display." >&2
    exit 1
fi
if sed 's/\x1b\[[0-9;]*m//g' "$LOG" | grep -q ' ERROR '; then
    echo "rerun_screenshot: warning: the viewer logged errors (an error toast may be in the picture):" >&2
    sed 's/\x1b\[[0-9;]*m//g' "$LOG" | grep -A4 ' ERROR ' | head -20 >&2
fi
python3 - "$RAW" "$png" "$window" <<'EOF'
import sys
from PIL import Image
raw, out, window = sys.argv[1:]
size = tuple(int(v) for v in window.split("x"))
im = Image.open(raw).convert("RGB")
if im.size != size:
    im = im.resize(size, Image.LANCZOS)
im.save(out, optimize=True)
print("wrote %s (%dx%d, viewer captured %dx%d)" % ((out,) + size + Image.open(raw).size))
EOF
