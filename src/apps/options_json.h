#pragma once
// Every option of the System and of the front end as JSON, and back: report.json keeps them all in every mode,
// so that what a run did can be read from its report alone.
#include <nlohmann/json.hpp>

#include "frontend/frontend.h"
#include "slam/known_map_tracking.h"
#include "slam/system.h"

namespace mcslam::apps {

nlohmann::json ToJson(const slam::SystemOptions& options);
nlohmann::json ToJson(const frontend::FrontendOptions& options);
nlohmann::json ToJson(const slam::KnownMapOptions& options);  // {"tracker": ..., "smoother": ...}
// Fields missing from `j` keep the value `options` had; a field of the wrong type or an unknown enum value
// throws std::invalid_argument naming it.
void FromJson(const nlohmann::json& j, slam::SystemOptions* options);
void FromJson(const nlohmann::json& j, frontend::FrontendOptions* options);
void FromJson(const nlohmann::json& j, slam::KnownMapOptions* options);
// `base` with every value where `given` differs from `defaults` taken from `given` (objects compared field by
// field, down to their leaves): the options of an earlier run with the flags changed on this command line on top.
nlohmann::json OverlayChanges(nlohmann::json base, const nlohmann::json& defaults, const nlohmann::json& given);

}  // namespace mcslam::apps
