#!/usr/bin/env python3
"""Every #include "layer/..." in src/ names the file's own layer or one it declares (transitively) in its
CMakeLists.txt: `mcslam_layer(NAME ... DEPS mcslam::x ...)` or, for apps, target_link_libraries(... mcslam::x).
Exit 1 with one line per offending include; 0 when the layering holds. Usage: check_layers.py SRC_DIR"""
import pathlib
import re
import sys


def declared_deps(src: pathlib.Path) -> dict:
    deps = {}
    for cmake in sorted(src.glob("*/CMakeLists.txt")):
        layer = cmake.parent.name
        deps[layer] = set(re.findall(r"mcslam::([a-z_]+)", cmake.read_text())) - {layer}
    return deps


def closure(deps: dict, layer: str) -> set:
    seen, todo = set(), [layer]
    while todo:
        for d in deps.get(todo.pop(), ()):
            if d not in seen:
                seen.add(d)
                todo.append(d)
    return seen


def main() -> int:
    src = pathlib.Path(sys.argv[1])
    deps = declared_deps(src)
    if not deps:
        print(f"check_layers: no layer CMakeLists.txt under {src}")
        return 2
    bad = []
    for layer in sorted(deps):
        allowed = closure(deps, layer) | {layer}
        for f in sorted((src / layer).rglob("*")):
            if f.suffix not in (".h", ".cc", ".cu", ".cuh"):
                continue
            for n, line in enumerate(f.read_text().splitlines(), 1):
                m = re.match(r'\s*#\s*include\s+"([a-z_]+)/', line)
                if m and m.group(1) in deps and m.group(1) not in allowed:
                    bad.append(f"{f.relative_to(src)}:{n}: layer '{layer}' includes '{m.group(1)}', "
                               f"which it does not depend on (it may use: {', '.join(sorted(allowed))})")
    for b in bad:
        print(b)
    print(f"check_layers: {len(deps)} layers, {len(bad)} include(s) outside a layer's dependencies")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
