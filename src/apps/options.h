#pragma once
// Command-line flags shared by several subcommands.
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
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
// The first number in a small kernel file (/proc, /sys), or the one after `key` ("MemAvailable:", "VmRSS:");
// nullopt for a missing file, key or number ("max").
std::optional<uint64_t> ReadNumberFile(const char* path, const char* key = nullptr);

// Ctrl-C (SIGINT) and SIGTERM (what `timeout`, `kill` and job schedulers send): the first asks the running
// job to stop and write what it has; a second one kills.
void InstallInterruptHandler();
bool Interrupted();
std::string InterruptedMessage();  // "interrupted by SIGTERM (outputs written)", ...

// Exit statuses (docs/hostile_input.md lists them), so that a script can tell a bad input from a run that could
// not start from its sequence, and from one that was stopped:
//   0    done
//   1    bad input, flags or files, or an error while running: the message on stderr names what
//   3    the run went through its sequence but never initialised (too little motion, too few features: the message
//        says which, NotInitialisedError); its outputs are written
//   128+signal  stopped by SIGINT (130) or SIGTERM (143); the outputs computed so far are written
//   100-114     the command line could not be parsed (CLI11's codes, e.g. 105 a value out of range, 109 extras)
inline constexpr int kExitError = 1;
inline constexpr int kExitNotInitialised = 3;

// Thrown where a job ends with a status other than kExitError; main prints what() and exits with code().
class ExitError : public std::runtime_error {
 public:
  ExitError(int code, const std::string& message) : std::runtime_error(message), code_(code) {}
  int code() const { return code_; }

 private:
  int code_;
};

// The status and message of a stop by a signal, to throw once the outputs are written.
ExitError InterruptedError();

}  // namespace mcslam::apps
