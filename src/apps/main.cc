#include <malloc.h>

#include <cstdio>
#include <exception>

#include <CLI/CLI.hpp>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "apps/commands.h"
#include "apps/options.h"

int main(int argc, char** argv) {
  // A frame's large buffers (images, pyramids, corner responses: 0.1-2 MB each at 640x480 to 1241x376) come from
  // the heap and are reused frame after frame, instead of fresh pages mapped for each and returned when freed:
  // glibc maps an allocation over its threshold (128 KB at first, raised only after a larger mapped block is
  // freed), and each fresh page costs a page fault (docs/tuning.md: KITTI 06 2.53 -> 2.42 s). The heap keeps up to 256 MB of freed memory.
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  // Logs and warnings on stderr; stdout carries only the results (a run's summary line, eval's figures), so
  // that scripts can read them.
  spdlog::set_default_logger(spdlog::stderr_color_mt("mcslam"));
  spdlog::set_pattern("[%Y-%m-%d %H:%M:%S.%e] [%l] %v");
  CLI::App app{"mcslam: monocular SLAM by Monte Carlo pose and structure estimation"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "mcslam 0.1.0");
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Log debug messages");
  app.parse_complete_callback([&] { spdlog::set_level(verbose ? spdlog::level::debug : spdlog::level::info); });
  mcslam::apps::RegisterSynth(app);
  mcslam::apps::RegisterEval(app);
  mcslam::apps::RegisterRun(app);
  mcslam::apps::RegisterBench(app);
  mcslam::apps::RegisterView(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const mcslam::apps::ExitError& e) {
    std::fprintf(stderr, "mcslam: %s%s\n", e.code() >= 128 ? "" : "error: ", e.what());
    return e.code();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mcslam: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
