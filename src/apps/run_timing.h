#pragma once
// Wall time and host CPU time of a run, for the run reports (issue #6: the paper's claim that the CPU stays
// free while the GPU does the Monte Carlo work; with the same report for every backend the two can be set
// side by side). CPU time is the whole process's, every thread included (getrusage(RUSAGE_SELF)): user and
// system time, so a host thread that spins while it waits for the device counts as busy.
#include <chrono>
#include <string>

#include <nlohmann/json.hpp>

namespace mcslam::apps {

struct RunTimes {
  double wall_s = 0;
  double cpu_user_s = 0, cpu_sys_s = 0;
  double cpu_s() const { return cpu_user_s + cpu_sys_s; }
  // cpu_s / wall_s: how many cores the run kept busy on average (1: one core all the time); 0 before any
  // wall time has passed.
  double cpu_ratio() const { return wall_s > 0 ? cpu_s() / wall_s : 0.0; }
};

// Starts at construction; Elapsed() is what the process used since then.
class RunClock {
 public:
  RunClock();
  RunTimes Elapsed() const;

 private:
  std::chrono::steady_clock::time_point wall0_;
  double user0_ = 0, sys0_ = 0;
};

// " wall_s=... cpu_s=... cpu_ratio=..." for the final summary line of a run (leading space included).
std::string RunTimesFields(const RunTimes& t);
// Adds wall_s, cpu_user_s, cpu_sys_s, cpu_s, cpu_ratio and hardware_threads (the cores cpu_ratio is out of)
// to a run report.
void AddRunTimes(const RunTimes& t, nlohmann::json* report);

}  // namespace mcslam::apps
