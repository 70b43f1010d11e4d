#!/usr/bin/env bash
# Packs what the GPU checks of issue #6 need into .gpu/ (git-ignored), for a machine that has an NVIDIA GPU
# and the CUDA driver but none of mcslam's libraries and no way to install them (the lent device machines).
#
#   scripts/gpu_bundle.sh            # here: builds build-gpu/ (CUDA for sm_90, no -march=native), packs .gpu/
#   bash .gpu/gpu_check.sh OUT_DIR   # there (with .gpu carried): runs the checks, writes OUT_DIR/gpu_check.log
#
# What goes in: mcslam and test_compute, every shared library they load, and glibc with its loader
# (used only where the machine's own glibc is older than the one built against). OpenCV's video and image-codec
# plugins pull in ~250 MB (ffmpeg, gstreamer, GDAL, ...) that the checks never call (they run on synthetic
# observations, no images): those libraries are replaced by stubs that define the same versioned symbols and
# trap if ever called (constructors and destructors excepted: they return, see below). JPEG and PNG are kept,
# so the image sequences run too. The check: the CUDA tests, `mcslam bench pose|points --compare` and a whole synthetic
# run on each backend (the figures issue #6 asks for), and the shared real sequences (7-Scenes, KITTI 06) when
# ../shared/data has them (MCSLAM_DATA). Needs: cmake, ninja, nvcc, binutils, gcc, python3, xz.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${BUILD:-$ROOT/build-gpu}
STAGE=$ROOT/.gpu/stage
CUDA_ARCHS=${CUDA_ARCHS:-90}
# The CPU backend for AVX2 + FMA (every x86-64 host of a Hopper GPU has them), so that the CPU side of the
# comparisons is vectorised as a user's build would be; MARCH=x86-64 for a machine without.
MARCH=${MARCH:-x86-64-v3}
DATA=${MCSLAM_DATA:-$ROOT/../shared/data}

cmake -S "$ROOT" -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release -DMCSLAM_NATIVE=ON -DMCSLAM_MARCH="$MARCH" \
  -DMCSLAM_CUDA=ON -DCMAKE_CUDA_ARCHITECTURES="$CUDA_ARCHS" -DCMAKE_EXE_LINKER_FLAGS=-Wl,--as-needed >/dev/null
# ALL_TESTS=1: every test binary too, so that the whole suite runs there (another CPU, 16 cores, AVX2 code).
if [[ "${ALL_TESTS:-0}" == 1 ]]; then ninja -C "$BUILD"; else ninja -C "$BUILD" mcslam test_compute; fi

rm -rf "$ROOT/.gpu"
mkdir -p "$STAGE/bin" "$STAGE/lib" "$STAGE/glibc" "$ROOT/.gpu/stubsrc"
cp "$BUILD/mcslam" "$BUILD/tests/test_compute" "$STAGE/bin/"
if [[ "${ALL_TESTS:-0}" == 1 ]]; then
  cp "$BUILD"/tests/test_* "$STAGE/bin/"
  rm -f "$STAGE"/bin/*.cmake
fi
# The tests run mcslam from the path they were built with: the check links that path to the unpacked bundle.
echo "$BUILD" > "$STAGE/build_path"

python3 - "$STAGE" "$ROOT/.gpu/stubsrc" <<'EOF'
import os, re, shutil, subprocess, sys
stage, stubsrc = sys.argv[1], sys.argv[2]
bins = [os.path.join(stage, 'bin', b) for b in os.listdir(os.path.join(stage, 'bin'))]

def needed(path):
    out = subprocess.run(['readelf', '-d', path], capture_output=True, text=True, check=True).stdout
    return re.findall(r'\(NEEDED\)\s+Shared library: \[(.+?)\]', out)

# soname -> path, from the loader's cache and the CUDA toolkit.
paths = {}
for line in subprocess.run(['ldconfig', '-p'], capture_output=True, text=True, check=True).stdout.splitlines():
    m = re.match(r'\s+(\S+) \(libc6,x86-64.*\) => (\S+)', line)
    if m and m.group(1) not in paths: paths[m.group(1)] = m.group(2)
for d in ['/usr/local/cuda/lib64', '/usr/local/cuda/targets/x86_64-linux/lib']:
    if os.path.isdir(d):
        for f in os.listdir(d): paths.setdefault(f, os.path.join(d, f))

GLIBC = {'libc.so.6', 'libm.so.6', 'libdl.so.2', 'libpthread.so.0', 'librt.so.1', 'ld-linux-x86-64.so.2',
         'libresolv.so.2', 'libutil.so.1', 'libmvec.so.1'}
# The libraries behind OpenCV's video input and its rarer image codecs: stubbed.
PLUGINS = ('libopencv_videoio.so', 'libopencv_imgcodecs.so')  # any OpenCV version
KEEP_CODECS = {'libjpeg.so.62', 'libpng16.so.16', 'libwebp.so.7', 'libtiff.so.6', 'libopenjp2.so.7'}
stubs = {}   # soname -> set of (symbol, version or None) the kept libraries import from it
kept, todo = set(), list(bins)
while todo:
    f = todo.pop()
    for so in needed(f):
        if so in GLIBC or so in kept or so in stubs: continue
        if os.path.basename(f).startswith(PLUGINS) and so not in KEEP_CODECS and not so.startswith('libopencv_') \
                and so not in ('libstdc++.so.6', 'libgcc_s.so.1'):
            stubs[so] = set()
            continue
        if so not in paths: sys.exit(f'gpu_bundle: cannot find {so} (needed by {f})')
        kept.add(so)
        dst = os.path.join(stage, 'lib', so)
        shutil.copy2(os.path.realpath(paths[so]), dst)
        todo.append(dst)

# What the kept libraries import from each stubbed one: their undefined dynamic symbols that the real
# library defines (with the version they ask for).
defined = {}
for so in stubs:
    out = subprocess.run(['nm', '-D', '--defined-only', paths[so]], capture_output=True, text=True).stdout
    defined[so] = {l.split()[-1].split('@')[0] for l in out.splitlines() if l.strip()}
for so in kept:
    f = os.path.join(stage, 'lib', so)
    if not (set(needed(f)) & set(stubs)): continue
    out = subprocess.run(['nm', '-D', '--undefined-only', f], capture_output=True, text=True).stdout
    for l in out.splitlines():
        sym = l.split()[-1]
        name, _, ver = sym.partition('@')
        ver = ver.lstrip('@') or None
        if ver and ver.startswith('GLIBC'): continue
        for s in stubs:
            if name in defined[s]: stubs[s].add((name, ver))
for so, syms in stubs.items():
    base = os.path.join(stubsrc, so)
    versions = sorted({v for _, v in syms if v})
    with open(base + '.s', 'w') as f:
        f.write('.text\n')
        for name, _ in sorted(syms):
            # Constructors, destructors and GDAL's driver registration return at once: OpenCV's image codecs
            # build one decoder of every kind (the EXR one holds an OpenEXR object, the GDAL one registers
            # GDAL's drivers) before reading any image. Any other call traps.
            body = 'ret' if (name.startswith('_ZN') and re.search(r'[CD][0-2]E', name)) or name == 'GDALAllRegister' \
                else 'ud2'
            f.write(f'.globl {name}\n.type {name},@function\n{name}:\n  {body}\n')
    with open(base + '.map', 'w') as f:
        if not versions:
            f.write('{ global: *; };\n')
        else:
            # Each symbol in one version node: the one asked for, or the first for an unversioned import.
            node = {}
            for n, v in sorted(syms, key=lambda x: (x[1] is None, x)):
                node.setdefault(n, v or versions[0])
            for v in versions:
                names = sorted(n for n, vv in node.items() if vv == v)
                f.write(f'{v} {{ global: {"; ".join(names) + ";" if names else ""} }};\n')
    subprocess.run(['gcc', '-shared', '-nostdlib', '-o', os.path.join(stage, 'lib', so), base + '.s',
                    f'-Wl,-soname,{so}', f'-Wl,--version-script,{base}.map'], check=True)
for so in GLIBC:
    if so in paths:
        shutil.copy2(os.path.realpath(paths[so]), os.path.join(stage, 'glibc', so))
    elif so in ('libc.so.6', 'ld-linux-x86-64.so.2'):
        sys.exit(f'gpu_bundle: cannot find {so} to carry')
print(f'gpu_bundle: {len(kept)} libraries kept, {len(stubs)} stubbed: {" ".join(sorted(stubs))}')
EOF

cp "$ROOT/scripts/gpu_check.sh" "$ROOT/.gpu/gpu_check.sh"
# The real sequences the check runs end to end on each backend, when they are here (about 30 MiB).
for seq in 7scenes_redkitchen_frames000-299 kitti_odometry_06_frames000-050 ${ALL_TESTS:+tum_rgbd_fr3_long_office_household_1hz}; do
  [[ -d "$DATA/$seq" ]] && mkdir -p "$ROOT/.gpu/data" && cp -r "$DATA/$seq" "$ROOT/.gpu/data/"
done
tar -C "$STAGE" -cf - . | xz -6 -T0 > "$ROOT/.gpu/bundle.tar.xz"
rm -rf "$STAGE" "$ROOT/.gpu/stubsrc"
echo "gpu_bundle: .gpu/bundle.tar.xz $(du -m "$ROOT/.gpu/bundle.tar.xz" | cut -f1) MiB; on the GPU machine: bash .gpu/gpu_check.sh OUT_DIR"
