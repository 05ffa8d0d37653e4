#!/usr/bin/env bash
# Speed side by side with MuJoCo on the same models, in one run (the machine is
# noisy: compare only figures measured together).
# Usage: benches/mujoco_side_by_side.sh PATH/TO/anchors/mujoco [WORKDIR]
# The anchor folder (run.sh, bench.c, *.xml) installs MuJoCo from PyPI into a venv.
set -euo pipefail
anchor=${1:?usage: $0 PATH/TO/anchors/mujoco [WORKDIR]}
work=${2:-${TMPDIR:-/tmp}/longreach-mujoco-anchor}
cd "$(dirname "$0")/.."
echo "== longreach (criterion, release)"
cargo bench --bench rig -- --warm-up-time 2 --measurement-time 5 rig_step 2>&1 | grep -E "^rig_step|time:|thrpt:"
echo "== MuJoCo 4.0 (implicitfast, dt = 1 ms)"
bash "$anchor/run.sh" "$work"
echo "== longreach again (noise check)"
cargo bench --bench rig -- --warm-up-time 2 --measurement-time 5 rig_step 2>&1 | grep -E "^rig_step|time:|thrpt:"
