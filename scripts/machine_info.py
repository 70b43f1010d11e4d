"""The machine a doc's figures were measured on: the cores this process may use, the CPU's model and its widest
vector unit. Results move with it (the default build is native: the vector width changes the last bits, and the
cells of chaotic scenarios with them)."""
import os


def describe():
    cores = len(os.sched_getaffinity(0))
    try:
        info = open("/proc/cpuinfo").read()
    except OSError:
        return f"{cores} cores"
    model = next((l.split(":", 1)[1].strip() for l in info.splitlines() if l.startswith("model name")), "unknown CPU")
    flags = next((l.split(":", 1)[1].split() for l in info.splitlines() if l.startswith("flags")), [])
    width = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "SSE"
    return f"{cores} cores ({model}, {width})"
