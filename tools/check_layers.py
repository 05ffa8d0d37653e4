#!/usr/bin/env python3
"""The layering ARCHITECTURE.md states, checked: which workspace crate may depend on
which (from `cargo metadata`), and no cycle between the modules of a crate (top-level
modules, and the submodules of every module folder).

Run from the repository root: `python3 tools/check_layers.py`. Exit 1 on a violation.
"""

import json
import re
import subprocess
import sys
from pathlib import Path

# Workspace crates each crate may depend on (normal and build dependencies; dev
# dependencies are free). Keep in step with ARCHITECTURE.md.
ALLOWED = {
    "longreach-rope": set(),
    "longreach-drive": {"longreach-rope"},
    "longreach-scenario": {"longreach-rope", "longreach-drive"},
    "longreach-plot": set(),
    "longreach-ident": {"longreach-rope", "longreach-drive", "longreach-scenario", "longreach-arm"},
    "longreach-arm": {"longreach-rope", "longreach-drive", "longreach-scenario"},
    "longreach-viz": {"longreach-arm", "longreach-drive", "longreach-ident", "longreach-rope"},
    "longreach": None,  # the CLI: any crate of the workspace
}


def crate_violations():
    meta = json.loads(
        subprocess.run(
            ["cargo", "metadata", "--format-version", "1", "--no-deps", "--offline"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout
    )
    members = {p["name"]: p for p in meta["packages"]}
    out = []
    for name, pkg in sorted(members.items()):
        if name not in ALLOWED:
            out.append(f"crate {name} is not in the layering table of tools/check_layers.py")
            continue
        allowed = ALLOWED[name]
        for dep in pkg["dependencies"]:
            if dep["name"] not in members or dep.get("kind") == "dev":
                continue
            if allowed is not None and dep["name"] not in allowed:
                out.append(f"{name} depends on {dep['name']}, which ARCHITECTURE.md does not allow")
    return out, members


USE = re.compile(r"\bcrate::(\w+)")
SUPER = re.compile(r"\bsuper::(\w+)")


def strip_comments(text):
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return "\n".join(line.split("//")[0] for line in text.splitlines())


def module_files(path):
    """The files of module `path` (a file, or a folder with mod.rs)."""
    if path.is_dir():
        return sorted(path.rglob("*.rs"))
    return [path]


def cycles(graph):
    """Strongly connected components with more than one node (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def module_violations(src, label):
    out = []
    mods = {}
    for p in sorted(src.iterdir()):
        if p.name in ("lib.rs", "main.rs"):
            continue
        if p.is_dir() and (p / "mod.rs").exists():
            mods[p.name] = p
        elif p.suffix == ".rs":
            mods[p.stem] = p
    graph = {}
    for name, path in mods.items():
        refs = set()
        for f in module_files(path):
            refs |= set(USE.findall(strip_comments(f.read_text())))
        graph[name] = {r for r in refs if r in mods and r != name}
    for c in cycles(graph):
        out.append(f"{label}: modules {' <-> '.join(c)} use each other")
    # Submodules of every module folder: `super::x` between siblings.
    for name, path in mods.items():
        if path.is_dir():
            out += module_violations_dir(path, f"{label}::{name}")
    return out


def module_violations_dir(folder, label):
    out = []
    subs = {}
    for p in sorted(folder.iterdir()):
        if p.name == "mod.rs":
            continue
        if p.is_dir() and (p / "mod.rs").exists():
            subs[p.name] = p
        elif p.suffix == ".rs":
            subs[p.stem] = p
    graph = {}
    for name, path in subs.items():
        refs = set()
        for f in module_files(path):
            text = strip_comments(f.read_text())
            # `super::` from a file directly in this folder names a sibling.
            if f.parent == folder:
                refs |= set(SUPER.findall(text))
        graph[name] = {r for r in refs if r in subs and r != name}
    for c in cycles(graph):
        out.append(f"{label}: submodules {' <-> '.join(c)} use each other")
    for name, path in subs.items():
        if path.is_dir():
            out += module_violations_dir(path, f"{label}::{name}")
    return out


def main():
    problems, members = crate_violations()
    root = Path(".").resolve()
    for name, pkg in sorted(members.items()):
        src = Path(pkg["manifest_path"]).parent / "src"
        if src.is_dir():
            problems += module_violations(src, name)
    for p in problems:
        print("layering:", p)
    if problems:
        print(f"{len(problems)} layering problem(s); see ARCHITECTURE.md", file=sys.stderr)
        return 1
    print(f"layering: {len(members)} crates, dependencies as ARCHITECTURE.md states, no module cycles")
    return 0


if __name__ == "__main__":
    sys.exit(main())
