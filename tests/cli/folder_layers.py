#!/usr/bin/python3
"""folder_layers.py SOURCE_DIR: the folders' #include graph has no cycle. A node is a library
folder — core/<stage> (base, field, raycast, mesh, refine, merge, io, metrics; core/(top) for
pipeline), transport/<side> (reduction, delivery), adaptor, cli, viewer, miniapps — and an edge A → B that a file in A includes
one of B's (by path, or by file name where an include path finds it). Prints the edges; exit status 1, naming a cycle, where there is one."""
import os
import re
import sys

src = os.path.abspath(sys.argv[1])
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)


def node_of(path):
    rel = os.path.relpath(path, src).split(os.sep)
    if rel[0] == "core":
        if rel[1] == "src":
            return "core/" + rel[2] if len(rel) > 3 else "core/(top)"
        if rel[1] == "include":  # core/include/ldimesh/core/<stage>/...
            return "core/" + rel[4] if len(rel) > 5 else "core/(top)"
    if rel[0] == "transport" and len(rel) > 2:  # transport/<side>/{src,include}/...
        return "transport/" + rel[1]
    return rel[0]


# Headers by file name, for includes found through an include path ("serve.hpp" from cli/).
headers = {}
for top in ("core", "transport", "adaptor", "cli", "viewer", "miniapps"):
    for root, _, files in os.walk(os.path.join(src, top)):
        for f in files:
            if f.endswith((".hpp", ".h")):
                headers.setdefault(f, []).append(os.path.join(root, f))


def target_of(including, name):
    if name.startswith("ldimesh/core/"):
        parts = name.split("/")
        return "core/" + parts[2] if len(parts) > 3 else "core/(top)"
    if name.startswith("ldimesh/transport/"):
        found = {node_of(h) for h in headers.get(os.path.basename(name), []) if h.endswith(name)}
        return found.pop() if len(found) == 1 else "transport/?"
    if name in ("ldimesh/adaptor.hpp", "ldimesh.h"):
        return "adaptor"
    local = os.path.normpath(os.path.join(os.path.dirname(including), name))
    if os.path.exists(local):
        return node_of(local)
    found = {node_of(h) for h in headers.get(os.path.basename(name), []) if h.endswith(name)}
    return found.pop() if len(found) == 1 else None


edges = {}
for top in ("core", "transport", "adaptor", "cli", "viewer", "miniapps"):
    for root, _, files in os.walk(os.path.join(src, top)):
        for f in files:
            if not f.endswith((".cpp", ".hpp", ".h", ".c")):
                continue
            path = os.path.join(root, f)
            a = node_of(path)
            for name in INCLUDE.findall(open(path, errors="replace").read()):
                b = target_of(path, name)
                if b and b != a:
                    edges.setdefault(a, set()).add(b)
for a in sorted(edges):
    print(f"{a} -> {', '.join(sorted(edges[a]))}")
# Depth-first search for a cycle.
state, stack = {}, []


def visit(n):
    state[n] = 1
    stack.append(n)
    for m in sorted(edges.get(n, ())):
        if state.get(m) == 1:
            print("cycle: " + " -> ".join(stack[stack.index(m):] + [m]))
            sys.exit(1)
        if m not in state:
            visit(m)
    stack.pop()
    state[n] = 2


for n in sorted(edges):
    if n not in state:
        visit(n)
print("no include cycle between folders")
