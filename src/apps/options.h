#pragma once
// Command-line flags shared by several subcommands.
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include <CLI/CLI.hpp>

#include "compute/point_kernel.h"
#include "compute/pose_kernel.h"
#include "slam/pose_tracker.h"

namespace mcslam::apps {

// Digits only, fitting 64 bits: CLI11 would otherwise wrap "-3" to 2^64 - 3 or saturate a too long number
// silently (a seed, a count).
CLI::Validator UnsignedInteger();

// A finite number within [lo, hi], or (lo, hi] when lo_open; CLI11 puts the flag's name in front, so a refusal
// reads "--noise: must be >= 0, got -1" (CLI11's own range checks print the largest double in 309 digits and
// let inf through).
CLI::Validator FiniteNumber(double lo, bool lo_open, double hi, const std::string& wanted);
CLI::Validator NonNegative();  // >= 0
CLI::Validator Positive();     // > 0
CLI::Validator Between(double lo, double hi);  // in [lo, hi]

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

// Memory a new allocation can have without swapping or being killed: /proc/meminfo's MemAvailable, capped by the
// cgroup's limit less its use (a container's or a job's). nullopt when neither can be read.
std::optional<uint64_t> AvailableMemoryBytes();

// Ctrl-C (SIGINT) and SIGTERM (what `timeout`, `kill` and job schedulers send): the first asks the running
// job to stop and write what it has; a second one kills.
void InstallInterruptHandler();
bool Interrupted();
std::string InterruptedMessage();  // "interrupted by SIGTERM (outputs written)", ...

}  // namespace mcslam::apps
