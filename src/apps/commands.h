#pragma once
// Each subcommand of `mcslam` registers itself on the top-level CLI11 app. Commands are thin: they parse
// options and call the library. A command's callback throws on failure; main() turns that into a
// message on stderr and a non-zero exit.
#include <CLI/CLI.hpp>

namespace mcslam::apps {

void RegisterSynth(CLI::App& app);
void RegisterEval(CLI::App& app);
void RegisterRun(CLI::App& app);
void RegisterBench(CLI::App& app);
void RegisterView(CLI::App& app);
// `bench soak` (apps/bench_soak.cc), on the `bench` command.
void RegisterBenchSoak(CLI::App* bench);

}  // namespace mcslam::apps
