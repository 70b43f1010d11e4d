// report.json's options: every field of the System's and the front end's options written, and read back.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "apps/options_json.h"

namespace mcslam::apps {
namespace {

std::string ErrorOf(const nlohmann::json& j) {
  slam::SystemOptions o;
  try {
    FromJson(j, &o);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(OptionsJson, SystemOptionsRoundTripEveryFieldTheyHold) {
  slam::SystemOptions o;
  o.tracker.hypotheses = 4096;
  o.tracker.random = slam::RandomMode::kFresh;
  o.tracker.pivot = slam::PoseTrackerOptions::Pivot::kOrigin;
  o.tracker.sigma_rot_deg = 0.123456789012345;
  o.init.method = geometry::EssentialMethod::kFivePointOpenCV;
  o.init.settle_parallax_deg = 11;
  o.mapping.window = 7;
  o.mapping.adjust = false;
  o.smoother.alpha = 0.25;
  o.pose_method = slam::PoseMethod::kPnp;
  o.structure_method = slam::StructureMethod::kBundleAdjustment;
  o.seed = 99;
  const nlohmann::json j = ToJson(o);
  EXPECT_EQ(j["tracker"]["random"], "fresh");
  EXPECT_EQ(j["init"]["method"], "5point");
  EXPECT_EQ(j["pose_method"], "pnp");
  // Read into default options: the same JSON comes back, so every field written is read (doubles exactly:
  // nlohmann writes them with round-trip precision).
  slam::SystemOptions back;
  FromJson(nlohmann::json::parse(j.dump()), &back);
  EXPECT_EQ(ToJson(back), j);
  EXPECT_EQ(back.tracker.sigma_rot_deg, o.tracker.sigma_rot_deg);
  EXPECT_EQ(back.structure_method, slam::StructureMethod::kBundleAdjustment);
  EXPECT_FALSE(back.mapping.adjust);
}

TEST(OptionsJson, FrontendOptionsRoundTrip) {
  frontend::FrontendOptions o;
  o.max_features = 123;
  o.anchor_mismatch = frontend::FrontendOptions::AnchorMismatch::kReanchor;
  o.remap_ratio = 0.61;
  const nlohmann::json j = ToJson(o);
  EXPECT_EQ(j["anchor_mismatch"], "reanchor");
  frontend::FrontendOptions back;
  FromJson(j, &back);
  EXPECT_EQ(ToJson(back), j);
}

TEST(OptionsJson, MissingFieldsKeepTheirValue) {
  slam::SystemOptions o;
  o.mapping.samples = 512;
  FromJson(nlohmann::json{{"tracker", {{"hypotheses", 2048}}}}, &o);
  EXPECT_EQ(o.tracker.hypotheses, 2048);
  EXPECT_EQ(o.mapping.samples, 512);
  EXPECT_EQ(o.tracker.rounds, slam::PoseTrackerOptions{}.rounds);
}

TEST(OptionsJson, BadValuesAreRefusedNamingTheField) {
  // nlohmann would read an unknown enumeration name as the first value: refused instead.
  EXPECT_NE(ErrorOf({{"tracker", {{"random", "bogus"}}}}).find("tracker.random"), std::string::npos);
  EXPECT_NE(ErrorOf({{"mapping", {{"no_such_option", 1}}}}).find("mapping.no_such_option"), std::string::npos);
  EXPECT_NE(ErrorOf({{"seed", "five"}}).find("system options"), std::string::npos);
  EXPECT_NE(ErrorOf(nlohmann::json::array()).find("an object is expected"), std::string::npos);
  slam::SystemOptions untouched;
  untouched.seed = 7;
  EXPECT_THROW(FromJson({{"seed", 8}, {"tracker", {{"pivot", "nowhere"}}}}, &untouched), std::invalid_argument);
  EXPECT_EQ(untouched.seed, 7u);  // nothing changes when anything is refused
}

}  // namespace
}  // namespace mcslam::apps

namespace mcslam::apps {
namespace {

// --options-from's merge: the report's values, except where this command line changed an option from its default.
TEST(OptionsJson, OverlayChangesKeepsTheBaseWhereNothingWasChanged) {
  const nlohmann::json defaults = {{"seed", 1}, {"tracker", {{"hypotheses", 262144}, {"rounds", 3}}}, {"name", "mc"}};
  const nlohmann::json base = {{"seed", 3}, {"tracker", {{"hypotheses", 16384}, {"rounds", 3}}}, {"name", "pnp"}};
  nlohmann::json given = defaults;
  EXPECT_EQ(OverlayChanges(base, defaults, given), base);  // no flag given: the report as it was
  given["seed"] = 4;
  given["tracker"]["rounds"] = 1;
  const nlohmann::json out = OverlayChanges(base, defaults, given);
  EXPECT_EQ(out["seed"], 4);
  EXPECT_EQ(out["tracker"]["rounds"], 1);
  EXPECT_EQ(out["tracker"]["hypotheses"], 16384);  // the report's, untouched beside a changed sibling
  EXPECT_EQ(out["name"], "pnp");
  // A field the report lacks (an older report) takes the command line's value when changed, else stays absent.
  const nlohmann::json old_report = {{"seed", 3}};
  const nlohmann::json merged = OverlayChanges(old_report, defaults, given);
  EXPECT_EQ(merged["tracker"]["rounds"], 1);
  EXPECT_FALSE(merged["tracker"].contains("hypotheses"));
  EXPECT_FALSE(merged.contains("name"));
}

}  // namespace
}  // namespace mcslam::apps
