// Camera paths for simulated users: where a user looks at time t. Deterministic (a function of
// t and the path's seed), so a load test can be repeated and every user's path differs.
//   orbit        a horizontal circle inside the scene's bounds, looking at the centre
//   random-walk  a smooth random wander through the bounds (sums of sines with random
//                frequencies and phases per user), looking around as it goes
//   FILE         keyframes "t ex ey ez tx ty tz [yfov_deg]" (seconds, eye, target), one per
//                line, '#' starts a comment; linear in between, looping over the file's duration
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "irradcast/common/world.h"

namespace irradcast {

struct CameraKeyframe {
  double t = 0.0;
  glm::vec3 eye{0.0f};
  glm::vec3 target{0.0f, 0.0f, -1.0f};
  float yfov = 0.6911112f;  // radians
};

// Reads a keyframe file. Throws irradcast::Error naming the file and line of a bad entry, and
// for fewer than one keyframe or times that do not increase.
std::vector<CameraKeyframe> load_camera_keyframes(const std::string& path);

class CameraPath {
 public:
  enum class Kind { Orbit, RandomWalk, Keyframes };

  // `phase` in [0, 1) places a user along the path (users spread out around an orbit);
  // `seed` draws a random walk.
  static CameraPath orbit(const Bounds& bounds, double period_s, double phase);
  static CameraPath random_walk(const Bounds& bounds, std::uint64_t seed);
  static CameraPath keyframes(std::vector<CameraKeyframe> frames, double phase);

  CameraPose at(double t) const;
  Kind kind() const { return kind_; }

 private:
  Kind kind_ = Kind::Orbit;
  glm::vec3 centre_{0.0f}, half_{1.0f};
  double period_ = 20.0, phase_ = 0.0;
  // Random walk: per axis three sines (frequency, phase), and the same for the yaw.
  float freq_[4][3] = {}, offs_[4][3] = {};
  std::vector<CameraKeyframe> frames_;
};

}  // namespace irradcast
