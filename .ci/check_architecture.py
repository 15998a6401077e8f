#!/usr/bin/env python3
"""Checks ARCHITECTURE.md against the code.

1. Its crate table has one row per workspace crate (folder and package as in `cargo metadata`),
   and the "may depend on" column equals each crate's workspace dependencies: normal ones
   unmarked, optional ones (behind a feature such as `testkit`) after "testkit:", dev-only ones
   after "dev:" (a crate listed as normal may also be a dev dependency).
2. No cycles between the top-level modules of any crate: module A of a crate "uses" module B when
   A's files mention `crate::B` or `super::B` at top level (or `B::` in lib.rs/main.rs re-exports
   are ignored). Cycles make a crate's parts impossible to read one at a time.
Exit status 1 with a list of differences. Usage: python3 .ci/check_architecture.py
"""
import json
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
meta = json.loads(subprocess.run(["cargo", "metadata", "--format-version", "1", "--no-deps", "--offline"],
                                 cwd=ROOT, capture_output=True, text=True, check=True).stdout)
members = {p["name"]: p for p in meta["packages"] if p["id"] in set(meta["workspace_members"])}
problems = []

# 1. The table.
rows = {}
with open(os.path.join(ROOT, "ARCHITECTURE.md"), encoding="utf-8") as f:
    for line in f:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) < 4 or not cells[0].startswith("`"):
            continue
        folder = cells[0].strip("`").rstrip("/")
        package = re.match(r"`([^`]+)`", cells[1]).group(1)
        deps = cells[-1]
        normal, optional, dev = set(), set(), set()
        for part in deps.split(";"):
            part = part.strip()
            target = normal
            if part.startswith("dev:"):
                target, part = dev, part[4:]
            elif part.startswith("testkit:"):
                target, part = optional, part[8:]
            target.update(re.findall(r"`(sonoflow[-\w]*)`", part))
        rows[package] = (folder, normal, optional, dev)

for name, p in sorted(members.items()):
    folder = os.path.relpath(os.path.dirname(p["manifest_path"]), ROOT)
    if name not in rows:
        problems.append(f"ARCHITECTURE.md has no row for {name} ({folder})")
        continue
    rfolder, rnormal, roptional, rdev = rows.pop(name)
    if rfolder != folder:
        problems.append(f"{name}: table says folder {rfolder}, cargo says {folder}")
    ws = [d for d in p["dependencies"] if d["name"] in members and d["name"] != name]
    normal = {d["name"] for d in ws if d["kind"] is None and not d["optional"]}
    optional = {d["name"] for d in ws if d["kind"] is None and d["optional"]}
    dev = {d["name"] for d in ws if d["kind"] == "dev"}
    if normal != rnormal:
        problems.append(f"{name}: dependencies {sorted(normal)}, table says {sorted(rnormal)}")
    if optional != roptional:
        problems.append(f"{name}: optional (testkit) dependencies {sorted(optional)}, table says testkit: {sorted(roptional)}")
    if not (dev - normal - optional) <= rdev or not rdev <= dev:
        problems.append(f"{name}: dev-dependencies {sorted(dev - normal)}, table says dev: {sorted(rdev)}")
for name in rows:
    problems.append(f"ARCHITECTURE.md lists {name}, which is not a workspace crate")

# 2. Module cycles within each crate.
def top_modules(src):
    mods = {}
    for entry in os.listdir(src):
        path = os.path.join(src, entry)
        if entry.endswith(".rs") and entry not in ("lib.rs", "main.rs"):
            mods[entry[:-3]] = [path]
        elif os.path.isdir(path) and entry != "bin":
            files = []
            for dp, _, fs in os.walk(path):
                files += [os.path.join(dp, x) for x in fs if x.endswith(".rs")]
            mods[entry] = files
    return mods

for name, p in sorted(members.items()):
    src = os.path.join(os.path.dirname(p["manifest_path"]), "src")
    if not os.path.isdir(src):
        continue
    mods = top_modules(src)
    edges = {m: set() for m in mods}
    for m, files in mods.items():
        for path in files:
            text = open(path, encoding="utf-8").read()
            text = text.split("#[cfg(test)]")[0]  # unit tests may reach anywhere
            text = re.sub(r"//[^\n]*", "", text)  # comments and doc links do not count
            for other in mods:
                if other != m and re.search(r"crate::" + other + r"\b", text):
                    edges[m].add(other)
    # cycle search
    state = {}
    def visit(m, stack):
        state[m] = 1
        for o in edges[m]:
            if state.get(o) == 1:
                cyc = stack[stack.index(o):] + [o]
                problems.append(f"{name}: module cycle " + " -> ".join(cyc))
            elif o not in state:
                visit(o, stack + [o])
        state[m] = 2
    for m in sorted(mods):
        if m not in state:
            visit(m, [m])

if problems:
    print("architecture check failed:")
    for p in problems:
        print("  " + p)
    sys.exit(1)
print(f"architecture: {len(members)} crates match ARCHITECTURE.md; no module cycles")
