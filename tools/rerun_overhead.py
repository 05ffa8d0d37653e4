#!/usr/bin/env python3
"""What `--rerun` costs a whole `longreach run` (or `bode`), measured in pairs.

Runs `longreach run SCENARIO --out DIR` (with `--command bode`: `longreach bode
SCENARIO --quiet`) without and with `--rerun save:FILE`, back to back, PAIRS times
(the order alternates), and prints the median and quartiles of the
per-pair ratio with/without: on a shared machine whose speed drifts by a factor of
two from one second to the next, a ratio of two neighbouring runs is steadier than
the ratio of two separately measured averages (what `cargo bench --bench rerun --
rerun_cli` gives).

Usage: tools/rerun_overhead.py [--bin target/release/longreach] [--pairs 40]
       [--command run|bode] SCENARIO...
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time


def timed(cmd):
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return 1e3 * (time.perf_counter() - t)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenarios", nargs="+", metavar="SCENARIO")
    ap.add_argument("--bin", default="target/release/longreach")
    ap.add_argument("--pairs", type=int, default=40)
    ap.add_argument("--command", choices=["run", "bode"], default="run")
    a = ap.parse_args()
    if not os.access(a.bin, os.X_OK):
        sys.exit(f"{a.bin}: not an executable; build it with `cargo build --release`")
    if a.pairs < 4:
        sys.exit("--pairs: at least 4")
    with tempfile.TemporaryDirectory() as d:
        for scenario in a.scenarios:
            if a.command == "run":
                off_cmd = [a.bin, "run", scenario, "--out", os.path.join(d, "off")]
            else:
                off_cmd = [a.bin, "bode", scenario, "--quiet"]
            rec_cmd = off_cmd + ["--rerun", "save:" + os.path.join(d, "run.rrd")]
            timed(off_cmd)  # warm the page cache
            off, rec, ratio = [], [], []
            for i in range(a.pairs):
                if i % 2 == 0:
                    o, r = timed(off_cmd), timed(rec_cmd)
                else:
                    r, o = timed(rec_cmd), timed(off_cmd)
                off.append(o)
                rec.append(r)
                ratio.append(r / o)
            q1, med, q3 = statistics.quantiles(ratio, n=4)
            print(f"{scenario}: {a.pairs} pairs; without {min(off):.1f} ms (min) / "
                  f"{statistics.median(off):.1f} ms (median), with --rerun "
                  f"{min(rec):.1f} / {statistics.median(rec):.1f} ms; per pair: median "
                  f"{100 * (med - 1):+.1f}% (quartiles {100 * (q1 - 1):+.1f}% .. "
                  f"{100 * (q3 - 1):+.1f}%)")


if __name__ == "__main__":
    main()
