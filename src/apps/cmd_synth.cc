// `mcslam synth --scenario paper --out DIR`: write the paper's synthetic sequence (§8.1) as files the other
// commands read: groundtruth.txt (TUM), map_gt.ply, camera.yaml, observations.txt.
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "apps/commands.h"
#include "sim/paper_scenario.h"
#include "sim/render.h"

namespace mcslam::apps {
namespace {

struct SynthArgs {
  std::string scenario = "paper";
  std::string out;
  sim::PaperScenarioOptions options;
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

// Digits only, fitting 64 bits: CLI11 would otherwise wrap "-3" or saturate a too long number silently.
CLI::Validator UnsignedInteger() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (text.empty() || text.find_first_not_of("0123456789") != std::string::npos)
          return "must be an integer >= 0, got " + text;
        errno = 0;
        std::strtoull(text.c_str(), nullptr, 10);
        if (errno == ERANGE) return "must fit in 64 bits, got " + text;
        return "";
      },
      "integer >= 0", "");
}

void RunSynth(const SynthArgs& a) {
  // Only one scenario exists; the flag's validator already refused any other name.
  const sim::SyntheticSequence seq = sim::MakePaperScenario(a.options);
  sim::WriteSyntheticSequence(seq, a.out);
  if (a.render) {
    sim::RenderOptions ro = a.render_options;
    ro.seed = a.options.seed;
    sim::RenderSequence(seq, a.out, ro);
  }
  // stdout carries exactly the summary line, so scripts can parse it.
  std::printf("%s scenario written to %s: %s\n", a.scenario.c_str(), a.out.c_str(),
              sim::Summarize(seq).ToString().c_str());
  std::fflush(stdout);
}

}  // namespace

void RegisterSynth(CLI::App& app) {
  auto args = std::make_shared<SynthArgs>();
  sim::PaperScenarioOptions& o = args->options;
  CLI::App* cmd = app.add_subcommand(
      "synth", "Write a synthetic sequence: ground truth (TUM), map (PLY), camera (YAML) and observations");
  cmd->add_option("--scenario", args->scenario, "Which synthetic world: paper (a textured box, the paper's §8.1)")
      ->check(CLI::IsMember({"paper"}))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "Output folder (created when missing)")->required();
  constexpr double kBig = 1e300;
  const double kMaxInt = 2147483647.0;
  cmd->add_option("--frames", o.frames, "Number of frames")
      ->check(FiniteNumber(1, false, kMaxInt, ">= 1"))
      ->capture_default_str();
  cmd->add_option("--fps", o.fps, "Frame rate; frame i has timestamp i/fps")
      ->check(FiniteNumber(0, true, kBig, "> 0"))
      ->capture_default_str();
  cmd->add_option("--noise", o.noise_px, "Gaussian pixel noise sigma, px")
      ->check(FiniteNumber(0, false, kBig, ">= 0"))
      ->capture_default_str();
  cmd->add_option("--outliers", o.outlier_fraction, "Fraction of observations that are wrong matches")
      ->check(FiniteNumber(0, false, 1, "in [0, 1]"))
      ->capture_default_str();
  cmd->add_option("--speed", o.speed, "Camera speed multiplier (1 = a person moving a webcam)")
      ->check(FiniteNumber(0, true, kBig, "> 0"))
      ->capture_default_str();
  cmd->add_option("--points", o.num_points, "Points on the box surfaces")
      ->check(FiniteNumber(1, false, kMaxInt, ">= 1"))
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Seed of the points, the path's phases, the noise and the outliers")
      ->check(UnsignedInteger())
      ->capture_default_str();
  cmd->add_flag("--render", args->render,
                "Also write images/NNNNNN.png: the textured box on a textured floor, ray-cast for each frame's pose");
  cmd->add_option("--image-noise", args->render_options.image_noise, "Grey-level noise of the rendered images")
      ->check(FiniteNumber(0.0, false, 255.0, "a number in [0, 255]"))
      ->capture_default_str();
  cmd->callback([args] { RunSynth(*args); });
}

}  // namespace mcslam::apps
