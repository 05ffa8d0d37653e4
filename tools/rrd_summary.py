#!/usr/bin/env python3
"""Reads a Rerun recording back with Rerun's own Python SDK (rerun-sdk 0.36.3) and
prints, as JSON, what every entity holds: row count (temporal rows; static ones
apart), timelines, components, for
scalar series the (time, [values]) pairs (one value per instance of a group of
series) and the series names, the (time, value) pairs of poses (`translations`,
`quaternions`), line strips (`strips`) and points (`points`), and the markdown of
text documents (`text`). The time is the first of the timelines `sim_time`,
`mode_time`, `frequency_mhz`, `mode_frame` the chunk has (None for static rows). Used by tests/cli/rerun_cli.rs; also handy to
check a recording by hand:

    python3 tools/rrd_summary.py run.rrd | python3 -m json.tool | less
"""
import json
import sys

import rerun as rr
import pyarrow as pa
import rerun.experimental as rrx


TIMELINES = ["sim_time", "mode_time", "frequency_mhz", "mode_frame"]
GEOMETRY = {
    "translations": "Transform3D:translation",
    "quaternions": "Transform3D:quaternion",
    "strips": "LineStrips3D:strips",
    "points": "Points3D:positions",
}


def index_values(column):
    """Seconds of a duration timeline (nanoseconds in the file: read as integers, since
    a time that is not a whole microsecond does not fit a Python timedelta), or the
    integers of a sequence timeline."""
    if pa.types.is_duration(column.type):
        return [None if v is None else v * 1e-9 for v in column.cast(pa.int64()).to_pylist()]
    return column.to_pylist()


def main(path):
    reader = rrx.RrdReader(path)
    out = {"sdk_version": rr.__version__, "blueprints": len(reader.blueprints()), "entities": {}}
    for chunk in reader.store().stream():
        rb = chunk.to_record_batch()
        names = rb.schema.names
        ent = out["entities"].setdefault(
            chunk.entity_path,
            {"rows": 0, "static_rows": 0, "static": False, "timelines": [], "components": [], "scalars": [], "names": []},
        )
        if chunk.is_static:
            ent["static"] = True
            ent["static_rows"] += chunk.num_rows
        else:
            ent["rows"] += chunk.num_rows
        for tl in chunk.timeline_names:
            if tl not in ent["timelines"]:
                ent["timelines"].append(tl)
        for n in names:
            if n.startswith("rerun.controls") or n in chunk.timeline_names:
                continue
            if n not in ent["components"]:
                ent["components"].append(n)
        index = next((t for t in TIMELINES if t in names), None)
        times = index_values(rb.column(index)) if index else [None] * rb.num_rows
        if "Scalars:scalars" in names and index:
            values = rb.column("Scalars:scalars").to_pylist()
            for t, v in zip(times, values):
                ent["scalars"].append([t, v if v else []])
        for key, column in GEOMETRY.items():
            if column in names:
                values = rb.column(column).to_pylist()
                ent.setdefault(key, []).extend([t, v] for t, v in zip(times, values))
        if "TextDocument:text" in names:
            text = rb.column("TextDocument:text").to_pylist()[-1]
            ent["text"] = text[0] if isinstance(text, list) and text else text
        if "SeriesLines:names" in names:
            for v in rb.column("SeriesLines:names").to_pylist():
                ent["names"] = v or []
    for ent in out["entities"].values():
        ent["scalars"].sort(key=lambda tv: tv[0])
        for key in GEOMETRY:
            if key in ent:
                ent[key].sort(key=lambda tv: -1.0 if tv[0] is None else tv[0])
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
