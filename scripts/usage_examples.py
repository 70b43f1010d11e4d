#!/usr/bin/env python3
"""Reruns the examples of the docs so that every quoted output is what the current build prints.

An example is a fenced code block right after a line `<!-- example -->`. In it, every line starting with `$ ` is
a command, run by bash from the repository root with build/ first on PATH (so `mcslam` is build/mcslam); the
lines after a command, up to the next command or the block's end, are replaced by its stdout (stderr is dropped
unless the command redirects it). `$ #` lines are comments and stay. A command that fails stops the script with
its stderr, leaving the file as it was.

Usage: python3 scripts/usage_examples.py [FILE.md ...]   (default: README.md and docs/*.md that have examples)
"""
import glob
import os
import pathlib
import subprocess
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
MARK = "<!-- example -->"


def run(command: str) -> list:
    env = dict(os.environ, PATH=f"{ROOT / 'build'}:{os.environ.get('PATH', '')}")
    p = subprocess.run(["bash", "-o", "pipefail", "-c", command], cwd=ROOT, env=env, capture_output=True, text=True)
    if p.returncode != 0:
        sys.stderr.write(p.stderr)
        raise SystemExit(f"usage_examples: `{command}` exited {p.returncode}")
    return p.stdout.rstrip("\n").split("\n") if p.stdout.strip() else []


def refresh(path: pathlib.Path) -> int:
    lines = path.read_text().split("\n")
    out, i, examples = [], 0, 0
    while i < len(lines):
        out.append(lines[i])
        if lines[i].strip() == MARK and i + 1 < len(lines) and lines[i + 1].startswith("```"):
            out.append(lines[i + 1])
            i += 2
            examples += 1
            while i < len(lines) and not lines[i].startswith("```"):
                line = lines[i]
                i += 1
                if line.startswith("$ #"):
                    out.append(line)
                elif line.startswith("$ "):
                    print(f"{path.name}: {line}", flush=True)
                    out.append(line)
                    out.extend(run(line[2:]))
                # any other line is the old output of the last command: dropped
            continue
        i += 1
    path.write_text("\n".join(out))
    return examples


def main() -> None:
    files = [pathlib.Path(f) for f in sys.argv[1:]] or [
        pathlib.Path(f) for f in [str(ROOT / "README.md")] + sorted(glob.glob(str(ROOT / "docs" / "*.md")))
        if MARK in pathlib.Path(f).read_text()]
    for f in files:
        n = refresh(f.resolve())
        print(f"usage_examples: {f}: {n} example(s) rerun")


if __name__ == "__main__":
    main()
