// `mcslam synth --scenario NAME --out DIR`: write a synthetic sequence of the scenario zoo (sim/scenarios.h;
// "paper" is the paper's §8.1) as files the other commands read: groundtruth.txt (TUM), map_gt.ply,
// camera.yaml, observations.txt, and with --render images/NNNNNN.png.
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "apps/commands.h"
#include "apps/options.h"
#include "io/observations_io.h"
#include "sim/paper_scenario.h"
#include "sim/render.h"
#include "sim/scenarios.h"

namespace mcslam::apps {
namespace {
namespace fs = std::filesystem;

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
  std::vector<double> lens;     // k1 k2 p1 p2 [k3]
  std::vector<double> fisheye;  // k1 k2 k3 k4
  bool render = false;
  sim::RenderOptions render_options;
};

// The sequence is built whole in memory, then written: refuse, before any work, a length that the machine's
// memory or the output's disk cannot hold (--frames 100000000 once grew to 24 GB and was killed by the kernel,
// taking the memory of everything else on the machine). The observations per frame are measured on the
// sequence's first frames (a sequence of N frames is the first N of a longer one), counted at twice the most
// seen there (the view changes along the path) and never more than every point, and held twice (the sequence,
// and the copy io writes). Measured: 50,000 paper frames peak at 1.03 GiB; this counts 1.6 GiB.
void CheckResources(const sim::ScenarioOptions& o, int frames, bool render, const std::string& out) {
  constexpr int kProbeFrames = 60;
  sim::ScenarioOptions probe = o;
  probe.frames = std::min(frames, kProbeFrames);
  const sim::SyntheticSequence head = sim::MakeScenario(probe);
  size_t most = 0;
  for (const sim::SyntheticFrame& f : head.frames) most = std::max(most, f.observations.size());
  const double per_frame_obs = std::min<double>(2.0 * static_cast<double>(most), head.points_in_world.size());
  const double memory = static_cast<double>(frames) *
                            (per_frame_obs * (sizeof(sim::SyntheticObservation) + sizeof(io::Observation)) +
                             sizeof(sim::SyntheticFrame) + sizeof(io::ObservationFrame) + sizeof(Pose) +
                             sizeof(double)) +
                        static_cast<double>(head.points_in_world.size()) * 2 * sizeof(Eigen::Vector3d);
  const std::optional<uint64_t> available = AvailableMemoryBytes();
  constexpr double kGiB = 1024.0 * 1024.0 * 1024.0;
  if (available && memory > 0.8 * static_cast<double>(*available))
    throw std::invalid_argument(fmt::format(
        "--frames {}: the sequence would need about {:.1f} GiB of memory ({:.0f} observations a frame), and this "
        "machine has {:.1f} GiB available; ask for fewer frames (or --points)",
        frames, memory / kGiB, per_frame_obs, static_cast<double>(*available) / kGiB));
  // observations.txt: about 60 characters an observation; a rendered PNG at most its raw grey bytes.
  const double disk = static_cast<double>(frames) *
                      (per_frame_obs * 60.0 + (render ? head.camera.width * head.camera.height : 0.0));
  std::error_code ec;
  fs::path existing = fs::absolute(out, ec);
  while (!existing.empty() && !fs::exists(existing, ec) && existing != existing.parent_path())
    existing = existing.parent_path();
  const fs::space_info space = fs::space(existing, ec);
  if (!ec && disk > static_cast<double>(space.available))
    throw std::invalid_argument(fmt::format(
        "--frames {}: the files would take about {:.1f} GiB and {} has {:.1f} GiB free; ask for fewer frames",
        frames, disk / kGiB, existing.string(), static_cast<double>(space.available) / kGiB));
}

void RunSynth(SynthArgs& a) {
  sim::ScenarioOptions& o = a.options;
  if (a.frames_flag->count() > 0) o.frames = a.frames;
  if (a.fps_flag->count() > 0) o.fps = a.fps;
  if (a.points_flag->count() > 0) o.num_points = a.points;
  if (!a.lens.empty() || !a.fisheye.empty()) {
    if (!a.fisheye.empty()) {
      o.lens = Distortion::Equidistant(a.fisheye[0], a.fisheye[1], a.fisheye[2], a.fisheye[3]);
    } else {
      const auto at = [&](size_t i) { return i < a.lens.size() ? a.lens[i] : 0.0; };
      o.lens = Distortion{at(0), at(1), at(2), at(3), at(4)};
    }
    try {
      o.Check();
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(std::string(a.fisheye.empty() ? "--distortion: " : "--fisheye: ") + e.what());
    }
  }
  // A path that ends (forward: the street) holds only so many frames; say which flags decide it.
  const sim::ScenarioInfo info = sim::DescribeScenario(o.name);
  const int frames = o.frames.value_or(info.frames);
  if (frames > o.MaxFrames()) {
    throw std::invalid_argument(fmt::format(
        "--frames: the {} scenario's path ends after {} frames at --speed {} and --fps {}, got {} frames{}", o.name,
        o.MaxFrames(), o.speed, o.fps.value_or(info.fps), frames, o.frames ? "" : " (its default)"));
  }
  CheckResources(o, frames, a.render, a.out);
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
  cmd->add_option("--distortion", args->lens,
                  "The lens the camera sees through, as a camera file gives it: K1 K2 P1 P2 [K3] (radial-tangential; "
                  "e.g. a EuRoC-like -0.28 0.07 0 0); the observations and the rendered images go through it and "
                  "camera.yaml declares it. Default: none")
      ->expected(4, 5)
      ->check(FiniteNumber(-1e6, false, 1e6, "a finite number"));
  cmd->add_option("--fisheye", args->fisheye,
                  "A fisheye lens instead (the equidistant / Kannala-Brandt model, ORB-SLAM3's KannalaBrandt8): K1 K2 "
                  "K3 K4 of theta_d = theta (1 + K1 theta^2 + ... + K4 theta^8); 0 0 0 0 is the ideal equidistant lens")
      ->expected(4)
      ->excludes("--distortion")
      ->check(FiniteNumber(-1e6, false, 1e6, "a finite number"));
  cmd->add_option("--image-scale", o.image_scale,
                  "Scales the camera's image size and focal length together: the same field of view at another "
                  "resolution (2: the paper's 320x240 becomes 640x480 at f = 1000 px)")
      ->check(FiniteNumber(0, true, 64, "in (0, 64]"))
      ->capture_default_str();
  cmd->add_option("--hfov", o.hfov_deg,
                  "The camera's horizontal field of view in degrees (the focal length set to give it, the image size "
                  "kept): a webcam's or a phone's 60-80 instead of the paper's narrow 35.5. Default: the scenario's")
      ->check(FiniteNumber(5, false, 150, "in [5, 150]"));
  cmd->add_flag("--render", args->render,
                "Also write images/NNNNNN.png: the scene's textured surfaces, ray-cast for each frame's pose");
  cmd->add_option("--image-noise", args->render_options.image_noise, "Grey-level noise of the rendered images")
      ->check(FiniteNumber(0.0, false, 255.0, "a number in [0, 255]"))
      ->capture_default_str();
  cmd->add_option("--edge-samples", args->render_options.edge_samples,
                  "Rays a pixel on an outline is shaded again from (its coverage as a sensor's pixel integrates it; "
                  "0: the 2x2 grid of rays only, as every render before this option)")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  cmd->add_option("--exposure-step", args->render_options.exposure_step,
                  "The rendered camera's exposure steps every 40 frames through 1, F, 1/F (an auto exposure that "
                  "jumps; 1: fixed)")
      ->check(FiniteNumber(0.1, false, 10.0, "a number in [0.1, 10]"))
      ->capture_default_str();
  cmd->add_option("--blur-sigma", args->render_options.blur_sigma_px,
                  "Two of every ten rendered frames (the 4th and 5th) are blurred by a Gaussian of this sigma, px "
                  "(a shake; 0: sharp)")
      ->check(FiniteNumber(0.0, false, 50.0, "a number in [0, 50]"))
      ->capture_default_str();
  cmd->callback([args] { RunSynth(*args); });
}

}  // namespace mcslam::apps
