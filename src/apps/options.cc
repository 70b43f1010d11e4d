#include "apps/options.h"

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

namespace mcslam::apps {

CLI::Validator UnsignedInteger() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos)
          return "must be an integer >= 0, got " + text;
        errno = 0;
        std::strtoull(text.c_str(), nullptr, 10);
        if (errno == ERANGE) return "must fit in 64 bits, got " + text;
        return "";
      },
      "integer >= 0", "");
}

CLI::Validator FiniteNumber(double lo, bool lo_open, double hi, const std::string& wanted) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        const bool parsed = !text.empty() && end != text.c_str() && *end == '\0';
        if (!parsed) return "must be a number " + wanted + ", got '" + text + "'";
        if (!std::isfinite(v) || v < lo || (lo_open && v == lo) || v > hi) return "must be " + wanted + ", got " + text;
        return "";
      },
      wanted, "");
}

CLI::Validator NonNegative() { return FiniteNumber(0, false, HUGE_VAL, ">= 0"); }
CLI::Validator Positive() { return FiniteNumber(0, true, HUGE_VAL, "> 0"); }
CLI::Validator Between(double lo, double hi) {
  return FiniteNumber(lo, false, hi, fmt::format("in [{}, {}]", lo, hi));
}

std::optional<uint64_t> ReadNumberFile(const char* path, const char* key) {
  std::ifstream in(path);
  std::string token;
  while (in >> token) {
    if (key != nullptr && token != key) continue;
    if (key != nullptr && !(in >> token)) return std::nullopt;
    char* end = nullptr;
    errno = 0;
    const unsigned long long v = std::strtoull(token.c_str(), &end, 10);
    if (end == token.c_str() || errno == ERANGE) return std::nullopt;
    return static_cast<uint64_t>(v);
  }
  return std::nullopt;
}

std::optional<uint64_t> AvailableMemoryBytes() {
  std::optional<uint64_t> available;
  if (const auto kb = ReadNumberFile("/proc/meminfo", "MemAvailable:")) available = *kb * 1024;
  // cgroup v2, then v1 (whose "no limit" is a huge number, which the min leaves alone).
  std::optional<uint64_t> limit = ReadNumberFile("/sys/fs/cgroup/memory.max");
  std::optional<uint64_t> used = ReadNumberFile("/sys/fs/cgroup/memory.current");
  if (!limit) {
    limit = ReadNumberFile("/sys/fs/cgroup/memory/memory.limit_in_bytes");
    used = ReadNumberFile("/sys/fs/cgroup/memory/memory.usage_in_bytes");
  }
  if (limit) {
    const uint64_t left = *limit > used.value_or(0) ? *limit - used.value_or(0) : 0;
    available = available ? std::min(*available, left) : left;
  }
  return available;
}

void PoseFlags::Add(CLI::App* cmd) {
  cmd->add_option("--hypotheses", tracker.hypotheses, "Pose hypotheses per frame (the paper: 2^18)")
      ->check(CLI::Range(1, 1 << 26))
      ->capture_default_str();
  cmd->add_option("--seed", tracker.seed, "Random seed")->check(UnsignedInteger())->capture_default_str();
  cmd->add_option("--random", random, "Random numbers: 'table' (the paper's, made once) or 'fresh' (new each frame)")
      ->check(CLI::IsMember({"table", "fresh"}))
      ->capture_default_str();
  cmd->add_option("--rounds", tracker.rounds,
                  "Sampling rounds per frame at the same total budget (1 = the paper's one-shot sampling; 3 measured better, docs/pose_estimation.md)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  cmd->add_option("--sigma-rot-deg", tracker.sigma_rot_deg,
                  "Std of the rotation hypotheses per axis, degrees: the least spread (it grows with the measured "
                  "rotation of the last frame, --sigma-rot-motion)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_option("--sigma-rot-motion", tracker.sigma_rot_motion_scale,
                  "The rotation spread is at least this times the last frame's measured rotation (0: the paper's "
                  "fixed spread)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_option("--translation-prior", tracker.translation_prior_steps,
                  "The linearised translation that sets the translation spread (Eqs. 3-5) has a prior of this many "
                  "times the last tracked frame's step: directions the points leave free stay near the camera's "
                  "motion (0: none, the paper's)")
      ->check(NonNegative())
      ->capture_default_str();
  cmd->add_option("--retry-rot-scale", tracker.retry_rot_scale,
                  "A frame lost at the first try is scored again with a rotation spread this many times wider "
                  "(0: no second try)")
      ->check(CLI::Range(0.0, 100.0))
      ->capture_default_str();
  cmd->add_option("--retry-max-residual-ratio", tracker.retry_max_residual_ratio,
                  "The wider second try's pose is kept only when its inliers' median residual is at most this many "
                  "times the recent frames' (0: kept whenever enough points agree)")
      ->check(CLI::Range(0.0, 1000.0))
      ->capture_default_str();
  cmd->add_option("--sigma-trans-floor", tracker.sigma_trans_floor_m, "Floor of the translation spread, metres")
      ->check(Positive())
      ->capture_default_str();
  cmd->add_option("--inlier-px", tracker.inlier_threshold_px, "Inlier threshold on the residual, pixels")
      ->check(Positive())
      ->capture_default_str();
  cmd->add_option("--max-distance-px", tracker.max_distance_px,
                  "Cap on one point's contribution to the score, pixels (1e4: the paper's plain sum)")
      ->check(Between(1e-6, 1e6))
      ->capture_default_str();
}

slam::PoseTrackerOptions PoseFlags::Resolve() const {
  slam::PoseTrackerOptions o = tracker;
  o.random = slam::ParseRandomMode(random);
  o.Check();
  return o;
}

void AddBackendFlag(CLI::App* cmd, std::string* backend) {
  cmd->add_option("--backend", *backend, "Compute backend: cpu, cuda or auto (cuda when a GPU is present)")
      ->check(CLI::IsMember({"cpu", "cuda", "auto"}))
      ->capture_default_str();
}

namespace {
// Resolves --backend to the backend to use: "cpu"; "cuda", an error when it cannot be had (no CUDA build, no
// device) and never a silent fallback; "auto", CUDA when a device is present, else the CPU.
compute::BackendKind ResolveBackend(const std::string& backend) {
  if (backend == "cpu") return compute::BackendKind::kCpu;
  if (backend == "auto")
    return compute::CudaCompiled() && compute::CudaDeviceCount() > 0 ? compute::BackendKind::kCuda
                                                                      : compute::BackendKind::kCpu;
  if (backend != "cuda") throw std::invalid_argument("--backend " + backend + ": unknown backend (cpu, cuda or auto)");
  if (!compute::CudaCompiled())
    throw std::invalid_argument("--backend cuda: this build has no CUDA backend (nvcc was not found when it was configured)");
  if (compute::CudaDeviceCount() == 0)
    throw std::invalid_argument("--backend cuda: " + compute::CudaDeviceDescription() +
                                " (--backend cpu, or auto, runs on the CPU)");
  return compute::BackendKind::kCuda;
}
}  // namespace

std::unique_ptr<compute::PoseKernel> MakePoseKernelFor(const std::string& backend) {
  if (ResolveBackend(backend) == compute::BackendKind::kCpu) return compute::MakeCpuPoseKernel();
#ifdef MCSLAM_WITH_CUDA
  return compute::MakeCudaPoseKernel();
#else
  throw std::logic_error("--backend cuda resolved without a CUDA build");  // unreachable: CudaCompiled() is false
#endif
}

std::unique_ptr<compute::PointKernel> MakePointKernelFor(const std::string& backend) {
  if (ResolveBackend(backend) == compute::BackendKind::kCpu) return compute::MakeCpuPointKernel();
#ifdef MCSLAM_WITH_CUDA
  return compute::MakeCudaPointKernel();
#else
  throw std::logic_error("--backend cuda resolved without a CUDA build");  // unreachable: CudaCompiled() is false
#endif
}

namespace {
// The one piece of global state: a signal handler can reach nothing else. 0: none yet, else the signal.
std::atomic<int> g_signal{0};
extern "C" void OnStopSignal(int sig) {
  if (g_signal.exchange(sig) != 0) std::_Exit(128 + sig);  // the second one: stop now
}
}  // namespace

void InstallInterruptHandler() {
  std::signal(SIGINT, OnStopSignal);
  std::signal(SIGTERM, OnStopSignal);
}
bool Interrupted() { return g_signal.load() != 0; }
ExitError InterruptedError() { return ExitError(128 + g_signal.load(), InterruptedMessage()); }
std::string InterruptedMessage() {
  const int sig = g_signal.load();
  return fmt::format("interrupted by {} (outputs written)", sig == SIGTERM ? "SIGTERM" : sig == SIGINT ? "Ctrl-C (SIGINT)"
                                                                                                  : "a signal");
}

}  // namespace mcslam::apps
