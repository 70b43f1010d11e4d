#include "apps/options.h"

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <csignal>
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
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--sigma-rot-motion", tracker.sigma_rot_motion_scale,
                  "The rotation spread is at least this times the last frame's measured rotation (0: the paper's "
                  "fixed spread)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--sigma-trans-floor", tracker.sigma_trans_floor_m, "Floor of the translation spread, metres")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--inlier-px", tracker.inlier_threshold_px, "Inlier threshold on the residual, pixels")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--max-distance-px", tracker.max_distance_px,
                  "Cap on one point's contribution to the score, pixels (1e4: the paper's plain sum)")
      ->check(CLI::Range(1e-6, 1e6))
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
std::string InterruptedMessage() {
  const int sig = g_signal.load();
  return fmt::format("interrupted by {} (outputs written)", sig == SIGTERM ? "SIGTERM" : sig == SIGINT ? "Ctrl-C (SIGINT)"
                                                                                                  : "a signal");
}

}  // namespace mcslam::apps
