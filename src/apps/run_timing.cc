#include "apps/run_timing.h"

#include <sys/resource.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <thread>

#include <fmt/format.h>

namespace mcslam::apps {

namespace {

double Seconds(const timeval& tv) { return static_cast<double>(tv.tv_sec) + 1e-6 * static_cast<double>(tv.tv_usec); }

void ProcessCpu(double* user_s, double* sys_s) {
  rusage ru{};
  if (getrusage(RUSAGE_SELF, &ru) != 0)
    throw std::runtime_error(fmt::format("getrusage failed: {}", std::strerror(errno)));
  *user_s = Seconds(ru.ru_utime);
  *sys_s = Seconds(ru.ru_stime);
}

}  // namespace

RunClock::RunClock() : wall0_(std::chrono::steady_clock::now()) { ProcessCpu(&user0_, &sys0_); }

RunTimes RunClock::Elapsed() const {
  RunTimes t;
  t.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0_).count();
  double user = 0, sys = 0;
  ProcessCpu(&user, &sys);
  t.cpu_user_s = user - user0_;
  t.cpu_sys_s = sys - sys0_;
  return t;
}

std::string RunTimesFields(const RunTimes& t) {
  return fmt::format(" wall_s={:.3f} cpu_s={:.3f} cpu_ratio={:.2f}", t.wall_s, t.cpu_s(), t.cpu_ratio());
}

void AddRunTimes(const RunTimes& t, nlohmann::json* report) {
  nlohmann::json& j = *report;
  j["wall_s"] = t.wall_s;
  j["cpu_user_s"] = t.cpu_user_s;
  j["cpu_sys_s"] = t.cpu_sys_s;
  j["cpu_s"] = t.cpu_s();
  j["cpu_ratio"] = t.cpu_ratio();
  j["hardware_threads"] = std::thread::hardware_concurrency();
}

}  // namespace mcslam::apps
