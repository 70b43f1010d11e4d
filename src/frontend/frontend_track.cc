// The front end's tracking stage: Kalman prediction, pyramidal Lucas-Kanade with the forward-backward check,
// patch alignment with the birth patch, jolt recovery.
#include "frontend/frontend_impl.h"

namespace mcslam::frontend {

namespace {

// The exposure change between two frames, I_cur = gain I_prev, from the tracks that followed: each track's window
// gives the ratio of its mean intensities in the two frames, and the median over the tracks is robust to the
// occluded and slid ones. A pure gain: an exposure time scales the light, and a gamma curve keeps a scaling a
// scaling. n: how many windows were inside both frames and not black.
constexpr int kMinExposureWindows = 8;  // fewer followed tracks with texture: no exposure measured
struct Exposure {
  double gain = 1;
  int n = 0;
};
Exposure MeasureExposure(const cv::Mat& prev, const cv::Mat& cur, const std::vector<cv::Point2f>& from,
                         const std::vector<cv::Point2f>& to) {
  constexpr int kHalf = 7;
  std::vector<double> gains;
  auto mean = [](const cv::Mat& img, const cv::Point2f& p, double* m) {
    const int x = cvRound(p.x), y = cvRound(p.y);
    if (x - kHalf < 0 || y - kHalf < 0 || x + kHalf >= img.cols || y + kHalf >= img.rows) return false;
    *m = cv::mean(img(cv::Rect(x - kHalf, y - kHalf, 2 * kHalf + 1, 2 * kHalf + 1)))[0];
    return true;
  };
  for (size_t k = 0; k < from.size(); ++k) {
    double m0, m1;
    if (!mean(prev, from[k], &m0) || !mean(cur, to[k], &m1) || m0 < 8.0 || m1 < 8.0) continue;
    gains.push_back(m1 / m0);
  }
  Exposure e;
  e.n = static_cast<int>(gains.size());
  if (e.n > 0) e.gain = UpperMedianInPlace(&gains);
  return e;
}

}  // namespace

void Frontend::Impl::TrackFeatures(const cv::Mat& gray, const std::vector<cv::Mat>& pyramid, FrameResult* result) {
  FrameStats& st = result->stats;
  const size_t n = tracks.size();
  if (n == 0 || prev_pyramid.empty()) return;
  const FrontendOptions& o = options;
  const cv::Size win(o.window_px, o.window_px);
  const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, o.max_iterations, o.epsilon_px);
  const float w1 = static_cast<float>(size.width - 1), h1 = static_cast<float>(size.height - 1);
  auto clamp_to_image = [&](cv::Point2f p) {
    p.x = std::clamp(p.x, 0.0f, w1);
    p.y = std::clamp(p.y, 0.0f, h1);
    return p;
  };
  const float b = static_cast<float>(o.track_border_px);
  auto outside = [&](const cv::Point2f& p) { return !(p.x >= b && p.y >= b && p.x <= w1 - b && p.y <= h1 - b); };

  std::vector<cv::Point2f> p0(n), start(n);
  for (size_t i = 0; i < n; ++i) {
    p0[i] = tracks[i].uv;
    const Eigen::Vector2d pred = tracks[i].kf.Predict(o.kalman_accel_sigma_px);
    start[i] = clamp_to_image(
        o.use_kalman_prediction ? cv::Point2f(static_cast<float>(pred.x()), static_cast<float>(pred.y())) : p0[i]);
  }

  enum Outcome : uint8_t { kOk, kOutside, kStatus, kForwardBackward, kAnchor };
  std::vector<cv::Point2f> p1(n);
  std::vector<float> err(n, 0.0f);
  std::vector<uint8_t> outcome(n, kStatus);

  // The previous frame's pyramid the tracks are followed from: the frame as it was, or brought to this frame's
  // exposure (below).
  const std::vector<cv::Mat>* from_pyramid = &prev_pyramid;
  std::vector<cv::Mat> exposed_pyramid;
  // Forward from the prediction, then back from where each track ended, started as far from its origin as
  // the forward result was from its own start (so that the round trip is not handed the answer).
  auto round_trip = [&](const std::vector<size_t>& which, int levels) {
    std::vector<cv::Point2f> a(which.size()), fwd(which.size());
    for (size_t k = 0; k < which.size(); ++k) {
      a[k] = p0[which[k]];
      fwd[k] = start[which[k]];
    }
    std::vector<uchar> status, status_back;
    std::vector<float> e, e_back;
    cv::calcOpticalFlowPyrLK(*from_pyramid, pyramid, a, fwd, status, e, win, levels - 1, criteria,
                             cv::OPTFLOW_USE_INITIAL_FLOW, o.min_eigen_threshold);
    std::vector<size_t> back_of;
    std::vector<cv::Point2f> from, back;
    for (size_t k = 0; k < which.size(); ++k) {
      const size_t i = which[k];
      p1[i] = fwd[k];
      err[i] = e[k];
      if (outside(fwd[k])) {
        outcome[i] = kOutside;
      } else if (!status[k]) {
        outcome[i] = kStatus;
      } else {
        back_of.push_back(i);
        from.push_back(fwd[k]);
        back.push_back(clamp_to_image(fwd[k] - (start[i] - p0[i])));
      }
    }
    if (from.empty()) return;
    cv::calcOpticalFlowPyrLK(pyramid, *from_pyramid, from, back, status_back, e_back, win, levels - 1, criteria,
                             cv::OPTFLOW_USE_INITIAL_FLOW, o.min_eigen_threshold);
    for (size_t k = 0; k < back_of.size(); ++k) {
      const size_t i = back_of[k];
      if (!status_back[k]) {
        outcome[i] = kStatus;
      } else if (cv::norm(back[k] - p0[i]) > o.max_forward_backward_px) {
        outcome[i] = kForwardBackward;
      } else {
        outcome[i] = kOk;
      }
    }
  };

  std::vector<size_t> all(n);
  for (size_t i = 0; i < n; ++i) all[i] = i;
  round_trip(all, o.pyramid_levels);
  // An exposure change (a camera's auto exposure, a light switched on) scales every intensity, and Lucas-Kanade,
  // which matches intensities as they are, loses the tracks or pulls them off (the paper scene with its exposure
  // stepped by 0.6-1.4x every 40 frames: 40-65 % of the tracks lost in each step, ATE 0.32 -> 2.2 cm). The gain is
  // measured on the tracks that followed; beyond exposure_min_change the previous frame is brought to this
  // frame's exposure and every track is followed again from it.
  if (o.exposure_min_change > 0) {
    std::vector<cv::Point2f> a, c;
    for (size_t i = 0; i < n; ++i)
      if (outcome[i] == kOk) a.push_back(p0[i]), c.push_back(p1[i]);
    Exposure e = MeasureExposure(prev_pyramid[0], gray, a, c);
    const int followed = e.n;
    // A step down can lose nearly every track (the rendered planar scenario, its clipped exposure stepped by 1/1.69:
    // 1 of 94 followed), and then the tracks that followed cannot measure it. The windows where the tracks were
    // predicted to be measure it instead; but a prediction off by more than a window (a jolt, a fast turn: the
    // rendered fast scenario loses most tracks in some frames with the light unchanged) compares other texture and
    // measures a gain of 0.84-1.12 where there is none. So a gain measured there is kept only when it follows the
    // tracks: most of them (a step compensated follows nearly all: 73 of 76 at 0.4x, 87 of 94 in that planar step),
    // at least kMinExposureWindows and twice as many as without it; else the frame goes on as before. (The last two
    // alone let the fast scenario rendered with noise, seed 1, take a gain of 0.86 in a jolt, the light unchanged.)
    const bool at_predictions = e.n < kMinExposureWindows;
    if (at_predictions) {
      a.clear(), c.clear();
      for (size_t i = 0; i < n; ++i)
        if (!outside(start[i])) a.push_back(p0[i]), c.push_back(start[i]);
      e = MeasureExposure(prev_pyramid[0], gray, a, c);
    }
    if (e.n >= kMinExposureWindows && std::abs(std::log(e.gain)) > std::log1p(o.exposure_min_change)) {
      // Only the round measured at the predictions can be undone: its state is kept to restore.
      std::vector<cv::Point2f> p1_before;
      std::vector<float> err_before;
      std::vector<uint8_t> outcome_before;
      if (at_predictions) p1_before = p1, err_before = err, outcome_before = outcome;
      cv::Mat exposed;
      prev_pyramid[0].convertTo(exposed, CV_8U, e.gain);
      cv::buildOpticalFlowPyramid(exposed, exposed_pyramid, win, static_cast<int>(prev_pyramid.size() / 2) - 1);
      from_pyramid = &exposed_pyramid;
      st.exposure_gain = static_cast<float>(e.gain);
      std::fill(outcome.begin(), outcome.end(), kStatus);
      round_trip(all, o.pyramid_levels);
      const auto now_followed = std::count(outcome.begin(), outcome.end(), kOk);
      if (at_predictions && (2 * now_followed < static_cast<std::ptrdiff_t>(n) || now_followed < kMinExposureWindows ||
                             now_followed < 2 * followed)) {
        p1 = std::move(p1_before), err = std::move(err_before), outcome = std::move(outcome_before);
        from_pyramid = &prev_pyramid;
        st.exposure_gain = 1;
      }
    }
  }
  // Tracks the shallow pyramid could not follow (a young track without a velocity, a jolt) get one more try
  // with a deeper pyramid; the forward-backward check still has the last word.
  if (o.retry_pyramid_levels > o.pyramid_levels) {
    std::vector<size_t> retry;
    for (size_t i = 0; i < n; ++i)
      if ((outcome[i] == kStatus || outcome[i] == kForwardBackward) && !outside(start[i])) retry.push_back(i);
    if (!retry.empty()) {
      st.retried = static_cast<int>(retry.size());
      round_trip(retry, o.retry_pyramid_levels);
      for (size_t i : retry) st.recovered += outcome[i] == kOk;
    }
    // A jolt of the camera (a sudden turn, a shake) moves the whole image away from every track's own
    // prediction, further than the deeper pyramid reaches; LK then fails, or worse settles in a local minimum
    // that the round trip confirms. The image's global shift, measured by phase correlation of a coarse
    // pyramid level (the whole image: it needs no track to have followed), gives the tracks that failed
    // twice a last try from where that shift puts them, when it is jolt_min_shift_px away from their
    // prediction. Only when a good part of the tracks failed together: a jolt loses most of them at once,
    // while a few failures are occlusions and changes of look (a car's forward motion) that no global shift
    // explains, and retrying those only gives LK another chance to settle somewhere wrong.
    std::vector<size_t> failed;
    for (size_t i = 0; i < n; ++i)
      if (outcome[i] == kStatus || outcome[i] == kForwardBackward) failed.push_back(i);
    if (o.jolt_recovery && !failed.empty() &&
        static_cast<double>(failed.size()) >= o.jolt_min_failed_fraction * static_cast<double>(n)) {
      const int level = std::min(2, static_cast<int>(std::min(pyramid.size(), from_pyramid->size()) / 2) - 1);
      if (level >= 0) {
        cv::Mat a, c;
        (*from_pyramid)[static_cast<size_t>(2 * level)].convertTo(a, CV_32F);
        pyramid[static_cast<size_t>(2 * level)].convertTo(c, CV_32F);
        if (a.size() == c.size() && a.cols >= 16 && a.rows >= 16) {
          if (hann.size() != a.size()) cv::createHanningWindow(hann, a.size(), CV_32F);
          double response = 0;
          const cv::Point2d d = cv::phaseCorrelate(a, c, hann, &response) * static_cast<double>(1 << level);
          const cv::Point2f shift(static_cast<float>(d.x), static_cast<float>(d.y));
          std::vector<size_t> again;
          for (size_t i : failed) {
            const cv::Point2f from = clamp_to_image(p0[i] + shift);
            if (outside(from) || cv::norm(from - start[i]) < o.jolt_min_shift_px) continue;
            start[i] = from;
            again.push_back(i);
          }
          if (!again.empty()) {
            round_trip(again, o.retry_pyramid_levels);
            for (size_t i : again) st.jolt_recovered += outcome[i] == kOk;
          }
        }
      }
    }
  }

  // Alignment with the birth patches (each track on its own: in parallel, the result independent of the order).
  const auto t_anchor = Clock::now();
  std::vector<uint8_t> reanchor(n, 0), aligned_ok(n, 0), mismatch(n, 0);
  std::vector<float> anchor_shift(n, 0.0f), sharpness_ratio(n, -1.0f);
  if (o.anchor_every > 0) {
    std::vector<size_t> due;
    for (size_t i = 0; i < n; ++i)
      if (outcome[i] == kOk && !tracks[i].anchor.empty() && (tracks[i].age + 1) % o.anchor_every == 0) due.push_back(i);
    // Float pixels: the alignment's bilinear samples are then vector gathers (the same values as from the 8-bit
    // frame, so the same result up to float rounding; 1.6x faster than 8-bit samples, bench_patch_align).
    if (!due.empty()) gray.convertTo(gray_float, CV_32F);
    // The image's noise (measured by Process: image_noise.h) lowers the correlation a patch can reach.
    const float noise_variance = st.noise_grey * st.noise_grey;
    tbb::parallel_for(size_t{0}, due.size(), [&](size_t k) {
      const size_t i = due[k];
      cv::Point2f aligned = p1[i];
      const AnchorOutcome a = AlignWithAnchor(gray_float, tracks[i].anchor, p1[i], o, &aligned, &tracks[i].anchor_linear,
                                                &sharpness_ratio[i], noise_variance);
      if (a == AnchorOutcome::kNotAligned) return;  // too near the edge: the LK position stands this frame
      if (a == AnchorOutcome::kMismatch) {
        mismatch[i] = 1;  // decided below, from the frame's count
        return;
      }
      if (a == AnchorOutcome::kReanchor) reanchor[i] = 1;
      anchor_shift[i] = static_cast<float>(cv::norm(aligned - p1[i]));
      aligned_ok[i] = 1;
      p1[i] = aligned;
    });
  }
  // A blurred frame (motion blur, a refocus) lowers every patch's sharpness against its birth patch at once; its
  // mismatches say nothing about the tracks, and a patch taken from it would be a blurred template that the sharp
  // frames after it align with off the point (the paper scene with two of every ten frames blurred, Gaussian
  // sigma 2 px: a third of the tracks took blurred patches in each such frame, ATE 0.32 -> 2.2 cm). Such a frame
  // keeps the LK positions of its mismatches and takes no new patch. The frame's measure is the median over its
  // aligned tracks of the sharpness ratio (AffinePatch::sharpness, invariant to gain and bias).
  std::vector<double> ratios;
  for (float r : sharpness_ratio)
    if (r >= 0) ratios.push_back(r);
  st.anchor_sharpness = static_cast<float>(UpperMedianInPlace(&ratios));
  // A blur that lasts (a lens out of focus, a long shake) is the look the camera has now: after
  // kMaxBlurredFrames frames in a row the frames count as sharp again, and the tracks take its patches.
  constexpr int kMaxBlurredFrames = 5;
  const bool soft = !ratios.empty() && st.anchor_sharpness < o.anchor_blur_ratio;
  blurred_run = soft ? blurred_run + 1 : 0;
  const bool blurred = soft && blurred_run <= kMaxBlurredFrames;
  st.blurred = blurred;
  // A mismatched track goes, or stays where LK put it and takes a new patch there (FrontendOptions::anchor_mismatch).
  const int mismatches = static_cast<int>(std::count(mismatch.begin(), mismatch.end(), 1));
  const int aligned_count = static_cast<int>(std::count(aligned_ok.begin(), aligned_ok.end(), 1)) + mismatches;
  using AM = FrontendOptions::AnchorMismatch;
  const bool keep_mismatched =
      blurred || o.anchor_mismatch == AM::kReanchor ||
      (o.anchor_mismatch == AM::kAuto && mismatches > o.anchor_auto_reanchor_fraction * aligned_count);
  for (size_t i = 0; i < n; ++i)
    if (mismatch[i] && keep_mismatched) reanchor[i] = !blurred;
    else if (mismatch[i]) outcome[i] = kAnchor;
    else if (blurred) reanchor[i] = 0;
  st.anchor_ms = MsSince(t_anchor);
  double sum_shift = 0;

  std::vector<Track> kept;
  kept.reserve(n);
  double sum_pred = 0, sum_disp = 0;
  std::vector<Look> lost_looks;
  std::vector<size_t> lost_described;  // the entries of result->lost that lost_looks describe
  for (size_t i = 0; i < n; ++i) {
    Track& t = tracks[i];
    bool lost = true;
    if (outcome[i] == kOutside || outside(start[i])) {
      ++st.lost_outside;
    } else if (outcome[i] == kStatus) {
      ++st.lost_status;
    } else if (outcome[i] == kForwardBackward) {
      ++st.lost_forward_backward;
    } else if (outcome[i] == kAnchor) {
      ++st.lost_anchor;
    } else if (o.max_patch_error > 0 && err[i] > o.max_patch_error) {
      ++st.lost_patch_error;
    } else {
      lost = false;
    }
    if (lost) {
      result->lost.push_back({t.id, ToEigen(p0[i]), t.descriptor});
      // Under DescribeOnly a map point's track can end before the frame that was to describe it (a track made a
      // map point in the frame before, at 1 Hz or in a fast turn): it is described in its birth frame, or where it
      // was last seen, so that it can be looked for again.
      if (describe_only && !t.descriptor && listed.count(t.id)) {
        lost_looks.push_back(LookOf(t, prev_pyramid[0], p0[i]));
        lost_described.push_back(result->lost.size() - 1);
      }
      continue;
    }
    sum_pred += cv::norm(p1[i] - start[i]);
    sum_disp += cv::norm(p1[i] - p0[i]);
    t.kf.Update(ToEigen(p1[i]), o.kalman_measurement_sigma_px);
    t.uv = p1[i];
    if (aligned_ok[i]) {
      ++st.anchored;
      sum_shift += anchor_shift[i];
    }
    if (reanchor[i]) {
      // Near the image's edge the new patch may not fit, or it may hold only an edge (empty): the track then
      // goes on unmonitored.
      t.anchor = MonitorPatch(gray, t.uv, o);
      t.anchor_linear = cv::Matx22f::eye();
      st.reanchored += !t.anchor.empty();
    }
    ++t.age;
    if (!t.birth_image.empty() && t.age >= BirthImageFrames()) t.birth_image.release();
    t.remapped = false;
    kept.push_back(std::move(t));
  }
  tracks = std::move(kept);
  if (!lost_looks.empty()) {
    std::vector<Descriptor> d;
    std::vector<char> ok;
    DescribeLooks(describer, lost_looks, &d, &ok);
    for (size_t k = 0; k < lost_looks.size(); ++k)
      if (ok[k]) result->lost[lost_described[k]].descriptor = d[k], ++st.described_listed;
  }
  if (st.anchored > 0) st.mean_anchor_shift_px = sum_shift / st.anchored;
  st.tracked = static_cast<int>(tracks.size());
  if (!tracks.empty()) {
    st.mean_prediction_error_px = sum_pred / static_cast<double>(tracks.size());
    st.mean_displacement_px = sum_disp / static_cast<double>(tracks.size());
  }
}


}  // namespace mcslam::frontend
