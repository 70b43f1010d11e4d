#!/usr/bin/env bash
# The GPU checks of issue #6, on a machine with an NVIDIA GPU, from the bundle that scripts/gpu_bundle.sh packs
# (copied there as .gpu/gpu_check.sh beside .gpu/bundle.tar.xz). Usage: bash .gpu/gpu_check.sh [OUT_DIR]
# Writes everything to OUT_DIR/gpu_check.log (default $OUT, else /tmp/gpu_check); about 3-5 minutes.
#   1. the CUDA tests (test_compute Cuda*: host-side checks and CPU/CUDA equivalence, a whole run included),
#   2. `mcslam bench pose --compare` at 2^18 hypotheses x 50 / 200 / 1000 points, once as the paper samples (one
#      round) and once as `mcslam run` does (3 rounds), and `bench points --compare` on one keyframe's
#      adjustment and on successive keyframes' (evaluations per second; per-frame / per-call latency including
#      the transfers; bytes sent per call),
#   3. the paper's noisy synthetic scenario run end to end on each backend, three times each (wall and CPU time),
#   4. the shared real sequences in the bundle, default settings, each backend GPU_CHECK_RUNS times (default 2),
#      once per variant of GPU_CHECK_VARIANTS (';'-separated extra `mcslam run` arguments; default: none).
# GPU_CHECK_ONLY=real runs step 4 alone (a diagnosis of whole runs, without the tests and benchmarks).
set -uo pipefail
HERE=$(cd "$(dirname "$0")" && pwd)
OUT_DIR=${1:-${OUT:-/tmp/gpu_check}}
mkdir -p "$OUT_DIR"
failed=0
step() {  # runs a command; a failure is remembered for the exit status
  "$@" || { echo "gpu_check: FAILED (exit $?): $*"; failed=1; }
}

main() {
W=/tmp/mcslam_gpu
rm -rf "$W" && mkdir -p "$W" && tar -xJf "$HERE/bundle.tar.xz" -C "$W" || { echo "gpu_check: cannot unpack $HERE/bundle.tar.xz"; return 1; }
nvidia-smi -L || echo "gpu_check: nvidia-smi failed"

# The machine's own loader when the binaries start with it (its glibc at least as new as the build's), else
# the carried glibc and loader, with the directory of the machine's libcuda after the bundle's libraries.
# GPU_CHECK_LOADER=carried forces the carried one (to try the bundle on a machine whose glibc would do).
RUN=(env "LD_LIBRARY_PATH=$W/lib")
if [[ "${GPU_CHECK_LOADER:-}" == carried ]] || ! probe=$("${RUN[@]}" "$W/bin/mcslam" --help 2>&1 >/dev/null); then
  cuda_dir=$(ldconfig -p 2>/dev/null | awk '/libcuda\.so\.1 .*x86-64/{print $NF; exit}')
  cuda_dir=${cuda_dir:+$(dirname "$cuda_dir")}
  for d in /usr/local/nvidia/lib64 /usr/lib/x86_64-linux-gnu /usr/lib64; do
    [[ -z "$cuda_dir" && -e "$d/libcuda.so.1" ]] && cuda_dir=$d
  done
  RUN=("$W/glibc/ld-linux-x86-64.so.2" --library-path "$W/lib:$W/glibc:${cuda_dir:-/usr/lib/x86_64-linux-gnu}")
  echo "gpu_check: using the carried glibc ($(ldd --version 2>/dev/null | head -1) here); the machine's loader said: ${probe:-(forced)}"
fi
mcslam() { "${RUN[@]}" "$W/bin/mcslam" "$@"; }

if [[ "${GPU_CHECK_ONLY:-}" != real ]]; then
echo "== CUDA tests"
step "${RUN[@]}" "$W/bin/test_compute" --gtest_filter='Cuda*'

if [[ -n "${GPU_CHECK_SUITE:-}" ]]; then
  # The whole suite (a bundle packed with ALL_TESTS=1): each test binary, the shared sequences from the bundle.
  # Left out: the tests that read or write video or open a webcam (one writes an MP4 overlay), which need
  # OpenCV's video plugins, stubbed in the bundle. GPU_CHECK_SUITE=only: nothing else.
  build=$(cat "$W/build_path")
  mkdir -p "$(dirname "$build")" && ln -sfn "$W/bin" "$build"
  echo "== whole test suite ($(nproc) cores, every test binary at once; tests run mcslam as $build/mcslam)"
  for t in "$W"/bin/test_*; do
    ( env MCSLAM_DATA="$HERE/data" "${RUN[@]}" "$t" --gtest_brief=1 \
        --gtest_filter='-*Video*:*Webcam*:CliImages.ImageFolderRunsEndToEndAndWritesEveryOutput' >"$t.log" 2>&1
      echo "exit status $?" >>"$t.log" ) &
  done
  wait
  for t in "$W"/bin/test_*; do
    [[ "$t" == *.log ]] && continue
    echo "-- $(basename "$t")"
    cat "$t.log"
    tail -1 "$t.log" | grep -q "exit status 0" || { echo "gpu_check: FAILED: $(basename "$t")"; failed=1; }
  done
  [[ "$GPU_CHECK_SUITE" == only ]] && return $failed
fi

echo "== pose kernel (2^18 hypotheses), point kernel"
lscpu | grep -E "^Model name|^CPU\(s\)|^Flags" | sed 's/^Flags:.*\(avx512f\).*/Flags: ... avx512f .../'
step mcslam bench pose --compare --points 50 200 1000 --repeats 31
step mcslam bench pose --compare --points 50 200 1000 --repeats 31 --rounds 3
step mcslam bench points --compare --repeats 31
step mcslam bench points --compare --repeats 31 --successive

echo "== pose kernel on the GPU against the number of hypotheses (200 points, 3 rounds as run does)"
for h in 16384 65536 262144 1048576 4194304; do
  step mcslam bench pose --backend cuda --hypotheses $h --points 200 --rounds 3 --repeats 31 | grep -v '^#'
done

echo "== whole synthetic run (paper scenario, 1 px noise, 10 % outliers), 3 times on each backend"
step mcslam synth --out "$W/synth" --noise 1 --outliers 0.1
for i in 1 2 3; do
  for b in cpu cuda; do
    echo -n "$b run $i: "
    if ! mcslam run "$W/synth" --backend "$b" --out "$W/run_$b" >"$W/run.log" 2>&1; then
      echo "failed:"
      tail -3 "$W/run.log"
      failed=1
    else
      tail -1 "$W/run.log"
    fi
  done
done
fi  # GPU_CHECK_ONLY
lscpu | grep -E "^Model name|^CPU\(s\)"
IFS=';' read -r -a variants <<<"${GPU_CHECK_VARIANTS:-}"
[[ ${#variants[@]} == 0 ]] && variants=("")
for seq in 7scenes_redkitchen_frames000-299 kitti_odometry_06_frames000-050; do
  [[ -d "$HERE/data/$seq" ]] || { echo "== $seq: not in the bundle, skipped"; continue; }
  cam=()
  [[ $seq == 7scenes* ]] && echo "525 525 320 240" > "$W/cam7.txt" && cam=(--camera "$W/cam7.txt")
  for variant in "${variants[@]}"; do
    read -r -a extra <<<"$variant"
    echo "== $seq, default settings${variant:+ and $variant}, ${GPU_CHECK_RUNS:-2} runs on each backend (stages_ms medians from report.json)"
    for ((i = 1; i <= ${GPU_CHECK_RUNS:-2}; ++i)); do
      for b in cpu cuda; do
        echo -n "$b run $i: "
        if ! mcslam run "$HERE/data/$seq" "${cam[@]}" "${extra[@]}" --backend "$b" --out "$W/real_$b" >"$W/run.log" 2>&1; then
          echo "failed:"; tail -3 "$W/run.log"; failed=1
        else
          tail -1 "$W/run.log"
          python3 -c "import json,sys; r=json.load(open(sys.argv[1])); print('  stages_ms median:', {k: round(v['median_ms'],2) for k,v in r['stages_ms'].items() if isinstance(v,dict) and v.get('median_ms') is not None})" "$W/real_$b/report.json" 2>/dev/null || true
        fi
      done
    done
  done
done
echo "== done ($([[ $failed == 0 ]] && echo "all steps passed" || echo "some steps FAILED"))"
return $failed
}

# The log is written by tee, which the pipeline waits for: the last lines are never lost.
main 2>&1 | tee "$OUT_DIR/gpu_check.log"
exit "${PIPESTATUS[0]}"
