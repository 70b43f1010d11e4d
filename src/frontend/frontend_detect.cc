// The front end's detection and remapping stage: Shi-Tomasi corners in the empty cells, lost map points found
// again by their descriptors near their projection (paper §6.4).
#include "frontend/frontend_impl.h"
#include "frontend/image_noise.h"

namespace mcslam::frontend {

void Frontend::Impl::DetectAndRemap(const cv::Mat& gray, std::span<const RemapRequest> remap, FrameResult* result) {
  FrameStats& st = result->stats;
  const FrontendOptions& o = options;
  const auto t_detect = Clock::now();
  const int W = gray.cols, H = gray.rows;
  const DetectionGrid grid = GridFor(o, W, H);
  const int cell_px = grid.cell_px;
  const int cells_x = (W + cell_px - 1) / cell_px, cells_y = (H + cell_px - 1) / cell_px;
  auto cell_of = [&](const cv::Point2f& p) {
    const int cx = std::clamp(static_cast<int>(p.x) / cell_px, 0, cells_x - 1);
    const int cy = std::clamp(static_cast<int>(p.y) / cell_px, 0, cells_y - 1);
    return cy * cells_x + cx;
  };
  std::vector<int> occupancy(static_cast<size_t>(cells_x * cells_y), 0);
  for (const Track& t : tracks) ++occupancy[static_cast<size_t>(cell_of(t.uv))];

  // Which requests can be tried at all (decided before any corner work, so that nothing is done for none).
  std::unordered_set<int64_t> live_ids;
  for (const Track& t : tracks) live_ids.insert(t.id);
  std::unordered_set<int64_t> seen_ids;
  std::vector<const RemapRequest*> requests;
  std::vector<const RemapRequest*> deferred;  // only_near_new_corner: decided once the new corners are known
  st.remap_requests = static_cast<int>(remap.size());
  const double rb = o.border_px;
  for (const RemapRequest& r : remap) {
    if (r.feature_id < 0 || r.feature_id >= next_id || live_ids.count(r.feature_id) ||
        !seen_ids.insert(r.feature_id).second) {
      ++st.remap_refused_id;
    } else if (!r.uv_px.allFinite() || r.uv_px.x() < rb || r.uv_px.y() < rb || r.uv_px.x() > W - 1 - rb ||
               r.uv_px.y() > H - 1 - rb) {
      ++st.remap_outside;
    } else {
      (r.only_near_new_corner ? deferred : requests).push_back(&r);
    }
  }

  // A blurred frame (FrameStats::blurred) takes no new corner: its corners lie off where the sharp frames after it
  // see them, and their birth patches would be blurred templates.
  const int budget = st.blurred ? 0 : o.max_features - static_cast<int>(tracks.size());
  bool any_empty_cell = false;
  for (int c : occupancy) any_empty_cell |= c == 0;
  if ((budget <= 0 || !any_empty_cell) && requests.empty()) {  // no new corner: every deferred request waits
    st.remap_deferred = static_cast<int>(deferred.size());
    st.detect_ms = MsSince(t_detect);
    // Nor are descriptors refreshed in such a frame; the listed tracks that have none are described all the same.
    std::vector<size_t> to_describe;
    AddListed(tracks.size(), &to_describe, &st);
    StartDescription(gray, std::move(to_describe), &st);
    return;
  }

  // Shi-Tomasi response and its local maxima, strongest first, away from the border and from every track.
  CornerResponse(gray, o.block_size, &eig);
  double max_response = 0;
  cv::minMaxLoc(eig, nullptr, &max_response);
  std::vector<Candidate> candidates;
  if (max_response > 0) {
    cv::dilate(eig, eig_dilated, cv::Mat());
    blocked.create(gray.size(), CV_8U);
    blocked.setTo(0);
    const int radius = static_cast<int>(std::ceil(grid.min_distance_px)) - 1;
    if (radius >= 0)
      for (const Track& t : tracks)
        cv::circle(blocked, cv::Point(cvRound(t.uv.x), cvRound(t.uv.y)), radius, 255, cv::FILLED);
    // A fraction of the frame's strongest response, and no less than what the frame's own noise reaches
    // (FrontendOptions::corner_noise_margin).
    double noise_floor = 0;
    if (o.corner_noise_margin > 0) {  // the unit noise's response is measured once, where it is used
      if (noise_corner_unit < 0) noise_corner_unit = NoiseCornerResponse(o.block_size, o.corner_noise_fraction);
      noise_floor = o.corner_noise_margin * noise_corner_unit * static_cast<double>(st.noise_grey) *
                    static_cast<double>(st.noise_grey);
    }
    const float threshold = static_cast<float>(std::max(o.quality_level * max_response, noise_floor));
    // Only cells that can take a new corner or that a remap window touches are searched.
    std::vector<char> search(occupancy.size(), 0);
    if (budget > 0)
      for (size_t c = 0; c < occupancy.size(); ++c) search[c] = occupancy[c] == 0;
    for (const RemapRequest* r : requests) {
      const int hw = o.remap_window_px;
      const int x0 = std::max(0, static_cast<int>(r->uv_px.x()) - hw) / cell_px;
      const int x1 = std::min(W - 1, static_cast<int>(r->uv_px.x()) + hw) / cell_px;
      const int y0 = std::max(0, static_cast<int>(r->uv_px.y()) - hw) / cell_px;
      const int y1 = std::min(H - 1, static_cast<int>(r->uv_px.y()) + hw) / cell_px;
      for (int cy = y0; cy <= y1; ++cy)
        for (int cx = x0; cx <= x1; ++cx) search[static_cast<size_t>(cy * cells_x + cx)] = 1;
    }
    for (int cy = 0; cy < cells_y; ++cy) {
      for (int cx = 0; cx < cells_x; ++cx) {
        if (!search[static_cast<size_t>(cy * cells_x + cx)]) continue;
        const int xb = std::max(o.border_px, cx * cell_px), xe = std::min(W - o.border_px, (cx + 1) * cell_px);
        const int yb = std::max(o.border_px, cy * cell_px), ye = std::min(H - o.border_px, (cy + 1) * cell_px);
        for (int y = yb; y < ye; ++y) {
          const float* e = eig.ptr<float>(y);
          const float* d = eig_dilated.ptr<float>(y);
          const uchar* m = blocked.ptr<uchar>(y);
          for (int x = xb; x < xe; ++x) {
            if (e[x] > threshold && e[x] == d[x] && !m[x])
              candidates.push_back(
                  {cv::Point2f(static_cast<float>(x), static_cast<float>(y)), e[x], cy * cells_x + cx});
          }
        }
      }
    }
    // Ties broken by position so that the result never depends on the sort's whims.
    std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
      if (a.response != b.response) return a.response > b.response;
      if (a.uv.y != b.uv.y) return a.uv.y < b.uv.y;
      return a.uv.x < b.uv.x;
    });
  }

  // New corners: only in cells without a track, a few per cell, min_distance apart, within the budget.
  std::vector<size_t> fresh;
  {
    std::vector<int> per_cell(occupancy.size(), 0);
    const double min_d2 = grid.min_distance_px * grid.min_distance_px;
    std::vector<std::vector<size_t>> accepted_in_cell(occupancy.size());
    for (size_t k = 0; k < candidates.size() && static_cast<int>(fresh.size()) < budget; ++k) {
      const Candidate& c = candidates[k];
      if (occupancy[static_cast<size_t>(c.cell)] > 0 || per_cell[static_cast<size_t>(c.cell)] >= o.max_new_per_cell)
        continue;
      // min_distance against the corners already taken here and in the neighbouring cells.
      bool close = false;
      const int cx = c.cell % cells_x, cy = c.cell / cells_x;
      const int reach = static_cast<int>(std::ceil(grid.min_distance_px / cell_px));
      for (int yy = std::max(0, cy - reach); yy <= std::min(cells_y - 1, cy + reach) && !close; ++yy)
        for (int xx = std::max(0, cx - reach); xx <= std::min(cells_x - 1, cx + reach) && !close; ++xx)
          for (size_t j : accepted_in_cell[static_cast<size_t>(yy * cells_x + xx)]) {
            const cv::Point2f d = candidates[j].uv - c.uv;
            if (d.x * d.x + d.y * d.y < min_d2) {
              close = true;
              break;
            }
          }
      if (close) continue;
      fresh.push_back(k);
      ++per_cell[static_cast<size_t>(c.cell)];
      accepted_in_cell[static_cast<size_t>(c.cell)].push_back(k);
    }
  }
  // A deferred request is tried when a new corner lies in its window (the corners in it are then its candidates
  // as for any request), and waits otherwise.
  {
    const float hw = static_cast<float>(o.remap_window_px);
    for (const RemapRequest* r : deferred) {
      const float u = static_cast<float>(r->uv_px.x()), v = static_cast<float>(r->uv_px.y());
      const bool near_new = std::any_of(fresh.begin(), fresh.end(), [&](size_t k) {
        return std::abs(candidates[k].uv.x - u) <= hw && std::abs(candidates[k].uv.y - v) <= hw;
      });
      if (near_new)
        requests.push_back(r);
      else
        ++st.remap_deferred;
    }
  }
  st.detect_ms = MsSince(t_detect);

  // Remapping (§6.4): the strongest new corners in the window around each projection, matched by SIFT.
  const auto t_remap = Clock::now();
  std::vector<std::pair<const RemapRequest*, size_t>> attached;  // request, candidate
  // The candidates described for the remapping, by index: a new track started at one of them takes that
  // descriptor instead of being described again (the same values: SiftDescriber::DescribeAll).
  std::unordered_map<size_t, std::optional<Descriptor>> descriptors;
  if (!requests.empty()) {
    std::vector<std::vector<size_t>> window_candidates(requests.size());
    const float hw = static_cast<float>(o.remap_window_px);
    for (size_t r = 0; r < requests.size(); ++r) {
      const float u = static_cast<float>(requests[r]->uv_px.x()), v = static_cast<float>(requests[r]->uv_px.y());
      // `candidates` is sorted by response: the first found are the strongest.
      for (size_t k = 0;
           k < candidates.size() && static_cast<int>(window_candidates[r].size()) < o.remap_max_candidates; ++k) {
        const cv::Point2f& p = candidates[k].uv;
        if (std::abs(p.x - u) <= hw && std::abs(p.y - v) <= hw) {
          window_candidates[r].push_back(k);
          descriptors.emplace(k, std::nullopt);
        }
      }
    }
    {  // every candidate of some window described at once (a candidate without a descriptor cannot match)
      std::vector<cv::Point2f> at;
      at.reserve(descriptors.size());
      for (const auto& [k, d] : descriptors) at.push_back(candidates[k].uv);
      std::vector<Descriptor> desc;
      std::vector<char> ok;
      describer.DescribeAll(gray, at, &desc, &ok);
      size_t n = 0;
      for (auto& [k, d] : descriptors) {
        if (ok[n]) d = desc[n];
        ++n;
      }
    }
    struct Match {
      float distance;
      size_t request;
      size_t candidate;
    };
    std::vector<Match> matches;
    std::vector<const Descriptor*> looks;
    for (size_t r = 0; r < requests.size(); ++r) {
      if (window_candidates[r].empty()) {
        ++st.remap_no_candidate;
        continue;
      }
      looks.clear();
      for (size_t k : window_candidates[r]) {
        const std::optional<Descriptor>& d = descriptors.at(k);
        looks.push_back(d ? &*d : nullptr);
      }
      std::optional<DescriptorMatch> m = MatchDescriptor(requests[r]->descriptor, looks, o);
      if (requests[r]->first_look)
        if (const auto m_first = MatchDescriptor(*requests[r]->first_look, looks, o);
            m_first && (!m || m_first->distance < m->distance))
          m = m_first;
      if (m) {
        matches.push_back({m->distance, r, window_candidates[r][m->index]});
      } else {
        ++st.remap_no_match;
      }
    }
    // One corner for one map point: the closest descriptors win.
    std::sort(matches.begin(), matches.end(), [](const Match& a, const Match& b) {
      return a.distance != b.distance ? a.distance < b.distance : a.request < b.request;
    });
    std::unordered_set<size_t> taken;
    for (const Match& m : matches) {
      if (!taken.insert(m.candidate).second) {
        ++st.remap_no_match;
        continue;
      }
      attached.emplace_back(requests[m.request], m.candidate);
    }
  }

  // New tracks (re-attached ones first), within the budget; new corners too near a re-attached one go.
  const size_t n_carried = tracks.size();
  std::vector<size_t> to_describe;
  for (const auto& [req, k] : attached) {
    if (static_cast<int>(tracks.size()) >= o.max_features) {
      ++st.remap_over_budget;
      continue;
    }
    Track t;
    t.id = req->feature_id;
    t.uv = candidates[k].uv;
    const auto [vel, sigma] = InitialVelocity(t.uv, n_carried);
    t.kf = ConstantVelocityKalman(ToEigen(t.uv), vel, o.kalman_measurement_sigma_px, sigma);
    t.remapped = true;
    t.descriptor = req->descriptor;  // its last look, whichever look matched (refreshed while it is tracked)
    if (o.anchor_every > 0) t.anchor = MonitorPatch(gray, t.uv, o);
    tracks.push_back(std::move(t));
    result->remapped_ids.push_back(req->feature_id);
  }
  st.remapped = static_cast<int>(result->remapped_ids.size());
  const double min_d2 = grid.min_distance_px * grid.min_distance_px;
  for (size_t k : fresh) {
    if (static_cast<int>(tracks.size()) >= o.max_features) break;
    bool near_attached = false;
    for (const auto& [req, ka] : attached) {
      const cv::Point2f d = candidates[ka].uv - candidates[k].uv;
      near_attached |= d.x * d.x + d.y * d.y < min_d2;
    }
    if (near_attached) continue;
    Track t;
    t.id = next_id++;
    t.uv = candidates[k].uv;
    const auto [vel, sigma] = InitialVelocity(t.uv, n_carried);
    t.kf = ConstantVelocityKalman(ToEigen(t.uv), vel, o.kalman_measurement_sigma_px, sigma);
    if (o.anchor_every > 0) t.anchor = MonitorPatch(gray, t.uv, o);
    if (const auto d = descriptors.find(k); d != descriptors.end() && d->second) {
      t.descriptor = d->second;  // described_at_age: 0, its age now
      ++st.described_for_remap;
    } else if (!describe_only) {
      to_describe.push_back(tracks.size());
    } else {
      t.birth_image = gray;  // described from it if listed soon (Track::birth_image)
      t.birth_uv = t.uv;
    }
    tracks.push_back(std::move(t));
    ++st.detected;
  }
  st.remap_ms = requests.empty() ? 0.0 : MsSince(t_remap);

  AddListed(n_carried, &to_describe, &st);
  // Tracks whose descriptor is descriptor_refresh_frames old are described again where they are now, when the
  // whole descriptor window is inside the image: a map point that is lost and comes back (remapping,
  // relocalisation) is then matched with how it looked when it was last seen, not at its birth. Under DescribeOnly
  // only the listed ones.
  if (o.descriptor_refresh_frames > 0) {
    const float margin = static_cast<float>(std::ceil(2.5 * 1.5 * o.descriptor_size_px));
    for (size_t i = 0; i < n_carried; ++i) {
      const Track& t = tracks[i];
      if (!t.descriptor || t.age - t.described_at_age < o.descriptor_refresh_frames) continue;
      if (describe_only && !listed.count(t.id)) continue;
      if (t.uv.x < margin || t.uv.y < margin || t.uv.x > static_cast<float>(W - 1) - margin ||
          t.uv.y > static_cast<float>(H - 1) - margin)
        continue;
      to_describe.push_back(i);
      ++st.refreshed;
    }
  }
  StartDescription(gray, std::move(to_describe), &st);
}


}  // namespace mcslam::frontend
