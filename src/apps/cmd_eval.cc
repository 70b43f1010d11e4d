#include "apps/commands.h"
namespace mcslam::apps {
void RegisterEval(CLI::App& app) { app.add_subcommand("eval", "Evaluate a trajectory (not yet)"); }
}  // namespace mcslam::apps
