#include "apps/commands.h"
namespace mcslam::apps {
void RegisterSynth(CLI::App& app) { app.add_subcommand("synth", "Write a synthetic scenario (not yet)"); }
}  // namespace mcslam::apps
