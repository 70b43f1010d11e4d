// ScoreInRounds (compute/pose_kernel.h): the pose search of one frame, shared by the tracker and the
// benchmark so that `mcslam bench pose --rounds` times what `mcslam run` does.
#include <cmath>
#include <stdexcept>
#include <string>

#include "compute/pose_kernel.h"

namespace mcslam::compute {

BestHypothesis ScoreInRounds(PoseKernel& kernel, PoseSampling s, const double sigma_q[4], const double sigma_t[3],
                             const PoseScoringPoints& points, const PoseScoringParams& params,
                             const NormalTable& normals, int hypotheses, int rounds, double shrink) {
  if (rounds < 1 || hypotheses < rounds)
    throw std::invalid_argument("ScoreInRounds: need 1 <= rounds <= hypotheses, got " + std::to_string(rounds) +
                                " rounds of " + std::to_string(hypotheses));
  BestHypothesis best;
  const int per_round = hypotheses / rounds;
  for (int round = 0; round < rounds; ++round) {
    const double f = std::pow(shrink, round);
    for (int k = 0; k < 4; ++k) s.sigma_q[k] = static_cast<float>(sigma_q[k] * f);
    for (int k = 0; k < 3; ++k) s.sigma_t[k] = static_cast<float>(sigma_t[k] * f);
    const int count = round + 1 == rounds ? hypotheses - per_round * round : per_round;
    best = kernel.Score(s, points, params, normals, count);
    if (best.index < 0) break;
    for (int k = 0; k < 4; ++k) s.q[k] = best.q[k];
    for (int k = 0; k < 3; ++k) s.t[k] = best.t[k];
  }
  return best;
}

}  // namespace mcslam::compute
