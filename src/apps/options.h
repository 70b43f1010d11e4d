#pragma once
// Command-line flags shared by several subcommands.
#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "slam/pose_tracker.h"

namespace mcslam::apps {

// Digits only, fitting 64 bits: CLI11 would otherwise wrap "-3" to 2^64 - 3 or saturate a too long number
// silently (a seed, a count).
CLI::Validator UnsignedInteger();

// Flags of the Monte Carlo pose estimator (--hypotheses, --seed, --random, --rounds, ...).
struct PoseFlags {
  slam::PoseTrackerOptions tracker;
  std::string random = "table";
  void Add(CLI::App* cmd);
  // Applies the string flags; throws std::invalid_argument naming the flag.
  slam::PoseTrackerOptions Resolve() const;
};

// --backend cpu|cuda|auto. cuda without a CUDA build or a device is an error, never a silent fallback.
std::unique_ptr<compute::PoseKernel> MakePoseKernelFor(const std::string& backend);
std::unique_ptr<compute::PointKernel> MakePointKernelFor(const std::string& backend);
void AddBackendFlag(CLI::App* cmd, std::string* backend);

// Ctrl-C (SIGINT) and SIGTERM (what `timeout`, `kill` and job schedulers send): the first asks the running
// job to stop and write what it has; a second one kills.
void InstallInterruptHandler();
bool Interrupted();
std::string InterruptedMessage();  // "interrupted by SIGTERM (outputs written)", ...

}  // namespace mcslam::apps
