# Two entry points for a newcomer on a fresh Debian machine:
#   make demo   installs what is missing, builds, runs the main job on the built-in synthetic scenario
#   make test   installs what is missing, builds, runs every test through ctest
BUILD ?= build
JOBS ?= $(shell nproc)
DEMO_OUT ?= out/demo
CMAKE_FLAGS ?=
# Unity builds (CMake joins each target's sources into a few translation units): the inline code every source
# instantiates again (Eigen, fmt, CLI11, json) is compiled once per unit instead of once per file. The native
# build took 367 CPU-s against 570 without, the sanitized one 492 against 784 (2 cores; docs/hostile_input.md).
# A plain `cmake` configure keeps one unit per file (the faster incremental rebuild, and every source is checked
# on its own includes).
UNITY ?= ON

.PHONY: all deps configure build test test-portable test-sanitize fuzz demo bench clean

all: build

deps:
	bash scripts/install-deps.sh

configure: deps
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=$(UNITY) $(CMAKE_FLAGS)

build: configure
	cmake --build $(BUILD) -j $(JOBS)

test: build
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS) --timeout 900
	@# ctest names skipped tests but not why: say once why the GPU tests skipped, if they did.
	@ctest --test-dir $(BUILD) -R '^Cuda' --verbose 2>/dev/null | grep -m1 -o 'no CUDA device[^"]*' | sed 's/^/GPU tests skipped: /' || true

# The same tests on a portable build (AVX2 + FMA, -march=x86-64-v3) instead of this CPU's widest vectors:
# accuracy bounds must hold on any x86-64 machine, not only on the one that built the default.
PORTABLE_BUILD ?= build-portable
test-portable: deps
	cmake -S . -B $(PORTABLE_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=$(UNITY) -DMCSLAM_MARCH=x86-64-v3 -DMCSLAM_CUDA=OFF $(CMAKE_FLAGS)
	cmake --build $(PORTABLE_BUILD) -j $(JOBS)
	ctest --test-dir $(PORTABLE_BUILD) --output-on-failure -j $(JOBS) --timeout 900

# The same tests built with AddressSanitizer + UndefinedBehaviorSanitizer (no CUDA, no benchmarks): a memory error,
# a leak or undefined behaviour anywhere a test reaches fails that test.
# Built with clang 14 (installed by deps, with its OpenMP runtime libomp-14-dev): it compiles the instrumented code
# faster than GCC -O3 (docs/hostile_input.md). SANITIZE_CXX=g++ builds it with GCC instead. One build folder per
# compiler: CMake keeps the compiler a folder was first configured with, and drops the other settings if made to
# change it.
SANITIZE_CXX ?= clang++-14
SANITIZE_BUILD ?= build-sanitize-$(notdir $(SANITIZE_CXX))
# SANITIZE_EXCLUDE: a ctest -E regex of tests to leave out (CI leaves out the slowest, see .ci/run); empty: all.
SANITIZE_EXCLUDE ?=
# OpenCV's gPhoto2 backend (DSLRs over USB), probed by every failed VideoCapture::open, leaks libusb's device list:
# not ours, and mcslam never needs that backend, so it is switched off here rather than the leak suppressed.
SANITIZE_ENV = ASAN_OPTIONS=detect_leaks=1:abort_on_error=0:strict_string_checks=1 \
               UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 OPENCV_VIDEOIO_PRIORITY_GPHOTO2=0
test-sanitize: deps
	CXX=$(SANITIZE_CXX) cmake -S . -B $(SANITIZE_BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=$(UNITY) -DMCSLAM_SANITIZE=ON -DMCSLAM_CUDA=OFF -DMCSLAM_BUILD_BENCH=OFF $(CMAKE_FLAGS)
	cmake --build $(SANITIZE_BUILD) -j $(JOBS)
	$(SANITIZE_ENV) ctest --test-dir $(SANITIZE_BUILD) --output-on-failure -j $(JOBS) --timeout 1800 \
	  $(if $(SANITIZE_EXCLUDE),-E '$(SANITIZE_EXCLUDE)')

# Every reader of outside files fuzzed (libFuzzer, clang, ASan + UBSan) for FUZZ_SECONDS each from fuzz/corpus/.
FUZZ_SECONDS ?= 30
fuzz: deps
	bash scripts/fuzz.sh $(FUZZ_SECONDS) build-fuzz

demo: build
	bash scripts/demo.sh $(BUILD)/mcslam $(DEMO_OUT)

clean:
	rm -rf $(BUILD) $(PORTABLE_BUILD) $(SANITIZE_BUILD) build-sanitize build-fuzz out
