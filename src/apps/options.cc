#include "apps/options.h"

#include <atomic>
#include <csignal>
#include <stdexcept>

namespace mcslam::apps {

void PoseFlags::Add(CLI::App* cmd) {
  cmd->add_option("--hypotheses", tracker.hypotheses, "Pose hypotheses per frame (the paper: 2^18)")
      ->check(CLI::Range(1, 1 << 26))
      ->capture_default_str();
  cmd->add_option("--seed", tracker.seed, "Random seed")->capture_default_str();
  cmd->add_option("--random", random, "Random numbers: 'table' (the paper's, made once) or 'fresh' (new each frame)")
      ->check(CLI::IsMember({"table", "fresh"}))
      ->capture_default_str();
  cmd->add_option("--rounds", tracker.rounds,
                  "Sampling rounds per frame at the same total budget (1 = the paper's one-shot sampling; 3 measured better, docs/pose_estimation.md)")
      ->check(CLI::Range(1, 16))
      ->capture_default_str();
  cmd->add_option("--sigma-rot-deg", tracker.sigma_rot_deg, "Std of the rotation hypotheses per axis, degrees")
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
      ->check(CLI::PositiveNumber)
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
// True for the CPU backend; throws when CUDA is asked for and cannot be had.
bool UseCpu(const std::string& backend) {
  const bool gpu = compute::CudaDeviceCount() > 0;
  if (backend == "cpu" || (backend == "auto" && !gpu)) return true;
  if (!compute::CudaCompiled())
    throw std::invalid_argument("--backend cuda: this build has no CUDA backend (nvcc was not found when it was configured)");
  if (!gpu) throw std::invalid_argument("--backend cuda: " + compute::CudaDeviceDescription());
  throw std::invalid_argument("--backend cuda: the CUDA kernels are not implemented yet (issue: CUDA backend)");
}
}  // namespace

std::unique_ptr<compute::PoseKernel> MakePoseKernelFor(const std::string& backend) {
  UseCpu(backend);
  return compute::MakeCpuPoseKernel();
}

std::unique_ptr<compute::PointKernel> MakePointKernelFor(const std::string& backend) {
  UseCpu(backend);
  return compute::MakeCpuPointKernel();
}

namespace {
std::atomic<bool> g_interrupted{false};  // the one piece of global state: a signal handler can reach nothing else
extern "C" void OnSigint(int) {
  if (g_interrupted.exchange(true)) std::_Exit(130);
}
}  // namespace

void InstallInterruptHandler() { std::signal(SIGINT, OnSigint); }
bool Interrupted() { return g_interrupted.load(); }

}  // namespace mcslam::apps
