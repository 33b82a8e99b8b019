#include "irradcast/client/camera_path.h"

#include <cmath>
#include <fstream>
#include <sstream>

#include "irradcast/common/error.h"
#include "irradcast/common/sampling.h"

namespace irradcast {

namespace {

constexpr double kTwoPi = 6.283185307179586;

CameraPose look(glm::vec3 eye, glm::vec3 target, float yfov) {
  CameraPose p;
  p.eye = eye;
  glm::vec3 f = target - eye;
  const float len = glm::length(f);
  p.forward = len > 1e-6f ? f / len : glm::vec3(0.0f, 0.0f, -1.0f);
  // Keep +Y up unless looking straight up or down.
  p.up = std::abs(p.forward.y) > 0.99f ? glm::vec3(0.0f, 0.0f, -1.0f) : glm::vec3(0, 1, 0);
  p.yfov = yfov;
  return p;
}

}  // namespace

std::vector<CameraKeyframe> load_camera_keyframes(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error("cannot read the camera path file '" + path + "'");
  std::vector<CameraKeyframe> frames;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream ss(line);
    std::vector<double> v;
    double x = 0.0;
    while (ss >> x) v.push_back(x);
    const bool rest_is_blank = (ss.eof() || (ss.clear(), (ss >> std::ws).eof()));
    if (v.empty() && rest_is_blank) continue;
    auto where = [&] { return path + ":" + std::to_string(number) + ": "; };
    if (!rest_is_blank) throw Error(where() + "not a number in '" + line + "'");
    if (v.size() != 7 && v.size() != 8)
      throw Error(where() + "expected 't ex ey ez tx ty tz [yfov_deg]', got " +
                  std::to_string(v.size()) + " numbers");
    for (double d : v)
      if (!std::isfinite(d)) throw Error(where() + "a number is not finite");
    CameraKeyframe k;
    k.t = v[0];
    k.eye = glm::vec3(v[1], v[2], v[3]);
    k.target = glm::vec3(v[4], v[5], v[6]);
    if (v.size() == 8) {
      if (v[7] <= 0.0 || v[7] >= 180.0) throw Error(where() + "yfov must be in (0, 180) degrees");
      k.yfov = static_cast<float>(v[7] * kTwoPi / 360.0);
    }
    if (glm::length(k.target - k.eye) < 1e-6f)
      throw Error(where() + "the eye and the target are the same point");
    if (!frames.empty() && k.t <= frames.back().t)
      throw Error(where() + "times must increase (" + std::to_string(k.t) + " after " +
                  std::to_string(frames.back().t) + ")");
    frames.push_back(k);
  }
  if (frames.empty()) throw Error("the camera path file '" + path + "' has no keyframes");
  return frames;
}

CameraPath CameraPath::orbit(const Bounds& bounds, double period_s, double phase) {
  CameraPath p;
  p.kind_ = Kind::Orbit;
  p.centre_ = 0.5f * (bounds.lo + bounds.hi);
  p.half_ = 0.5f * bounds.extent();
  p.period_ = period_s > 0.0 ? period_s : 20.0;
  p.phase_ = phase;
  return p;
}

CameraPath CameraPath::random_walk(const Bounds& bounds, std::uint64_t seed) {
  CameraPath p;
  p.kind_ = Kind::RandomWalk;
  p.centre_ = 0.5f * (bounds.lo + bounds.hi);
  p.half_ = 0.5f * bounds.extent();
  Rng rng(seed, 0x10ad);
  for (auto& axis : p.freq_)
    for (float& f : axis) f = 0.05f + 0.25f * rng.next_float();  // cycles per second
  for (auto& axis : p.offs_)
    for (float& o : axis) o = static_cast<float>(kTwoPi) * rng.next_float();
  return p;
}

CameraPath CameraPath::keyframes(std::vector<CameraKeyframe> frames, double phase) {
  if (frames.empty()) throw Error("a camera path needs at least one keyframe");
  CameraPath p;
  p.kind_ = Kind::Keyframes;
  p.frames_ = std::move(frames);
  p.phase_ = phase;
  return p;
}

CameraPose CameraPath::at(double t) const {
  switch (kind_) {
    case Kind::Orbit: {
      // A circle at 40% of the horizontal half extent, at the centre's height, looking at
      // the centre: inside a room, a user turning around in it.
      const double a = kTwoPi * (t / period_ + phase_);
      const glm::vec3 eye =
          centre_ + glm::vec3(0.4f * half_.x * static_cast<float>(std::cos(a)), 0.0f,
                              0.4f * half_.z * static_cast<float>(std::sin(a)));
      // Look past the centre, so the view sweeps the far walls.
      return look(eye, centre_ + (centre_ - eye), 0.6911112f);
    }
    case Kind::RandomWalk: {
      auto wave = [&](int axis) {
        float s = 0.0f;
        for (int k = 0; k < 3; ++k)
          s += std::sin(static_cast<float>(kTwoPi * t) * freq_[axis][k] + offs_[axis][k]);
        return s / 3.0f;  // in [-1, 1]
      };
      const glm::vec3 eye = centre_ + 0.6f * half_ * glm::vec3(wave(0), 0.5f * wave(1), wave(2));
      const float yaw = static_cast<float>(kTwoPi) * wave(3);
      const glm::vec3 dir(std::cos(yaw), -0.1f, std::sin(yaw));
      return look(eye, eye + dir, 0.6911112f);
    }
    case Kind::Keyframes: {
      const double t0 = frames_.front().t, span = frames_.back().t - t0;
      if (frames_.size() == 1 || span <= 0.0)
        return look(frames_.front().eye, frames_.front().target, frames_.front().yfov);
      double u = std::fmod(t + phase_ * span, span);
      if (u < 0.0) u += span;
      u += t0;
      std::size_t i = 0;
      while (i + 2 < frames_.size() && frames_[i + 1].t <= u) ++i;
      const CameraKeyframe &a = frames_[i], &b = frames_[i + 1];
      const float w = static_cast<float>((u - a.t) / (b.t - a.t));
      return look(glm::mix(a.eye, b.eye, w), glm::mix(a.target, b.target, w),
                  a.yfov + w * (b.yfov - a.yfov));
    }
  }
  return {};
}

}  // namespace irradcast
