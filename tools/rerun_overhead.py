#!/usr/bin/env python3
"""What `--rerun` costs a whole `longreach run` (or `bode`), measured in pairs.

Runs `longreach run SCENARIO --out DIR` (with `--command bode`: `longreach bode
SCENARIO --quiet`) without and with `--rerun save:FILE`, back to back, PAIRS times
(the order alternates; each recording is a new file), and prints the median and
quartiles of the per-pair ratio with/without, of wall time and of CPU time (user +
system, every thread: steadier on a busy machine, and what `bode`, whose runs keep
every core busy, pays). On a shared machine whose speed drifts by a factor of two
from one second to the next, a ratio of two neighbouring runs is steadier than the
ratio of two separately measured averages (what `cargo bench --bench rerun --
rerun_cli` gives).

Usage: tools/rerun_overhead.py [--bin target/release/longreach] [--pairs 40]
       [--command run|bode] SCENARIO...
"""

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time


def timed(cmd):
    """Wall time and CPU time (user + system, all threads) of `cmd`, ms."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = 1e3 * (time.perf_counter() - t)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = 1e3 * (after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return wall, cpu


def spread(ratios):
    q1, med, q3 = statistics.quantiles(ratios, n=4)
    return f"median {100 * (med - 1):+.1f}% (quartiles {100 * (q1 - 1):+.1f}% .. {100 * (q3 - 1):+.1f}%)"


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
            rrd = os.path.join(d, "run.rrd")
            rec_cmd = off_cmd + ["--rerun", "save:" + rrd]
            timed(off_cmd)  # warm the page cache
            off, rec, ratio, cpu_ratio = [], [], [], []
            for i in range(a.pairs):
                # Each recording is a new file: replacing one costs the file system
                # (ext4 frees the old blocks), not the logging.
                if os.path.exists(rrd):
                    os.remove(rrd)
                if i % 2 == 0:
                    o, r = timed(off_cmd), timed(rec_cmd)
                else:
                    r, o = timed(rec_cmd), timed(off_cmd)
                off.append(o[0])
                rec.append(r[0])
                ratio.append(r[0] / o[0])
                cpu_ratio.append(r[1] / o[1])
            print(f"{scenario}: {a.pairs} pairs; without {min(off):.1f} ms (min) / "
                  f"{statistics.median(off):.1f} ms (median), with --rerun "
                  f"{min(rec):.1f} / {statistics.median(rec):.1f} ms; per pair: wall "
                  f"{spread(ratio)}; CPU time {spread(cpu_ratio)}")

if __name__ == "__main__":
    main()
