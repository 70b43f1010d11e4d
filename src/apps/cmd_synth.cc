// `mcslam synth --scenario NAME --out DIR`: write a synthetic sequence of the scenario zoo (sim/scenarios.h;
// "paper" is the paper's §8.1) as files the other commands read: groundtruth.txt (TUM), map_gt.ply,
// camera.yaml, observations.txt, and with --render images/NNNNNN.png.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/options.h"
#include "sim/paper_scenario.h"
#include "sim/render.h"
#include "sim/scenarios.h"

namespace mcslam::apps {
namespace {

struct SynthArgs {
  std::string out;
  sim::ScenarioOptions options;
  // Options whose default is the scenario's: the value given, used only when the flag was.
  int frames = 0;
  double fps = 0;
  int points = 0;
  CLI::Option* frames_flag = nullptr;
  CLI::Option* fps_flag = nullptr;
  CLI::Option* points_flag = nullptr;
  bool render = false;
  sim::RenderOptions render_options;
};

// A finite number within [lo, hi], or (lo, hi] when lo_open. CLI11 puts the flag's name in front of the
// message, so a refusal reads "--noise: must be >= 0, got -1".
CLI::Validator FiniteNumber(double lo, bool lo_open, double hi, const std::string& wanted) {
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        const bool parsed = end != text.c_str() && *end == '\0';
        if (!parsed || !std::isfinite(v) || v < lo || (lo_open && v == lo) || v > hi)
          return "must be " + wanted + ", got " + text;
        return "";
      },
      wanted, "");
}

void RunSynth(SynthArgs& a) {
  sim::ScenarioOptions& o = a.options;
  if (a.frames_flag->count() > 0) o.frames = a.frames;
  if (a.fps_flag->count() > 0) o.fps = a.fps;
  if (a.points_flag->count() > 0) o.num_points = a.points;
  // A path that ends (forward: the street) holds only so many frames; say which flags decide it.
  const sim::ScenarioInfo info = sim::DescribeScenario(o.name);
  const int frames = o.frames.value_or(info.frames);
  if (frames > o.MaxFrames()) {
    throw std::invalid_argument(fmt::format(
        "--frames: the {} scenario's path ends after {} frames at --speed {} and --fps {}, got {} frames{}", o.name,
        o.MaxFrames(), o.speed, o.fps.value_or(info.fps), frames, o.frames ? "" : " (its default)"));
  }
  const sim::SyntheticSequence seq = sim::MakeScenario(o);
  sim::WriteSyntheticSequence(seq, a.out);
  if (a.render) {
    sim::RenderOptions ro = a.render_options;
    ro.seed = o.seed;
    sim::RenderSequence(seq, a.out, ro);
  }
  // stdout carries exactly the summary line, so scripts can parse it.
  std::printf("%s scenario written to %s: %s\n", o.name.c_str(), a.out.c_str(), sim::Summarize(seq).ToString().c_str());
  std::fflush(stdout);
}

// "paper 300, forward 120, ..." for the help of a flag whose default is the scenario's.
template <typename Field>
std::string PerScenario(Field field) {
  std::string text;
  for (const std::string& name : sim::ScenarioNames())
    text += (text.empty() ? "" : ", ") + name + " " + fmt::format("{}", field(sim::DescribeScenario(name)));
  return text;
}

}  // namespace

void RegisterSynth(CLI::App& app) {
  auto args = std::make_shared<SynthArgs>();
  sim::ScenarioOptions& o = args->options;
  CLI::App* cmd = app.add_subcommand(
      "synth", "Write a synthetic sequence: ground truth (TUM), map (PLY), camera (YAML) and observations");
  std::string names;
  for (const std::string& n : sim::ScenarioNames()) names += (names.empty() ? "" : ", ") + n;
  cmd->add_option("--scenario", o.name,
                  "Which synthetic world and motion (docs/scenarios.md): " + names +
                      "; paper is the paper's textured box (§8.1)")
      ->check(CLI::IsMember(sim::ScenarioNames()))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "Output folder (created when missing)")->required();
  constexpr double kBig = 1e300;
  const double kMaxInt = 2147483647.0;
  args->frames_flag =
      cmd->add_option("--frames", args->frames,
                      "Number of frames (default: the scenario's: " +
                          PerScenario([](const sim::ScenarioInfo& i) { return i.frames; }) + ")")
          ->check(FiniteNumber(1, false, kMaxInt, ">= 1"));
  args->fps_flag = cmd->add_option("--fps", args->fps,
                                   "Frame rate; frame i has timestamp i/fps (default: the scenario's: " +
                                       PerScenario([](const sim::ScenarioInfo& i) { return i.fps; }) + ")")
                       ->check(FiniteNumber(0, true, kBig, "> 0"));
  cmd->add_option("--noise", o.noise_px, "Gaussian pixel noise sigma, px")
      ->check(FiniteNumber(0, false, kBig, ">= 0"))
      ->capture_default_str();
  cmd->add_option("--outliers", o.outlier_fraction, "Fraction of observations that are wrong matches")
      ->check(FiniteNumber(0, false, 1, "in [0, 1]"))
      ->capture_default_str();
  cmd->add_option("--speed", o.speed, "Multiplies the scenario's own camera speed (1 = the scenario as designed)")
      ->check(FiniteNumber(0, true, kBig, "> 0"))
      ->capture_default_str();
  args->points_flag = cmd->add_option("--points", args->points,
                                      "Points on the scene's surfaces (default: the scenario's: " +
                                          PerScenario([](const sim::ScenarioInfo& i) { return i.num_points; }) + ")")
                          ->check(FiniteNumber(1, false, kMaxInt, ">= 1"));
  cmd->add_option("--seed", o.seed, "Seed of the points, the path, the world's layout, the noise and the outliers")
      ->check(UnsignedInteger())
      ->capture_default_str();
  cmd->add_flag("--render", args->render,
                "Also write images/NNNNNN.png: the scene's textured surfaces, ray-cast for each frame's pose");
  cmd->add_option("--image-noise", args->render_options.image_noise, "Grey-level noise of the rendered images")
      ->check(FiniteNumber(0.0, false, 255.0, "a number in [0, 255]"))
      ->capture_default_str();
  cmd->callback([args] { RunSynth(*args); });
}

}  // namespace mcslam::apps
