#include "irradcast/client/client_passes.h"

#include <chrono>

#include "irradcast/client/frame_gbuffer.h"
#include "irradcast/common/compositor.h"
#include "irradcast/common/error.h"

namespace irradcast {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

}  // namespace

void ClientPassOptions::validate() const {
  ssao_params.validate();
  reprojection.validate();
  if (reproject && !ssao)
    throw Error(
        "--reproject needs --ssao: the reprojection cache holds the SSAO result (the "
        "lightmap term is always looked up anew)");
}

ClientPasses::ClientPasses(ClientPassOptions options)
    : options_(options), cache_(options.reprojection) {
  options_.validate();
}

void ClientPasses::reset() {
  cache_.clear();
  frame_ = 0;
  dynamic_boxes_.clear();
}

namespace {

// The regions whose history a dynamic object's move made stale: the old and new boxes of every
// object whose box changed (all of them when one appeared or went), grown by `margin`.
std::vector<Bounds> moved_regions(const std::vector<Bounds>& before, const std::vector<Bounds>& now,
                                  float margin) {
  std::vector<Bounds> out;
  const auto grown = [margin](Bounds b) {
    b.lo -= glm::vec3(margin);
    b.hi += glm::vec3(margin);
    return b;
  };
  const bool same_set = before.size() == now.size();
  for (std::size_t i = 0; i < now.size(); ++i) {
    if (same_set && before[i].lo == now[i].lo && before[i].hi == now[i].hi) continue;
    out.push_back(grown(now[i]));
    if (same_set) out.push_back(grown(before[i]));
  }
  if (!same_set)
    for (const Bounds& b : before) out.push_back(grown(b));
  return out;
}

}  // namespace

ImageRGB ClientPasses::compose(const World& world, const RayScene& rays, const Atlas& atlas,
                               const std::vector<Lightmap>& lightmaps, const CameraPose& camera,
                               int width, int height, ClientFrameStats* stats,
                               const DynamicView* dynamic) {
  ClientFrameStats local;
  ClientFrameStats& st = stats ? *stats : local;
  st = ClientFrameStats{};
  const auto start = Clock::now();
  if (!options_.ssao) {
    ImageRGB image =
        irradcast::compose(world, rays, atlas, lightmaps, camera, width, height, nullptr, dynamic);
    st.trace_s = st.total_s = since(start);
    return image;
  }
  FrameGBuffer g = trace_frame(world, rays, atlas, lightmaps, camera, width, height, dynamic);
  st.trace_s = since(start);
  const float radius = options_.ssao_params.world_radius(world.bounds);
  if (options_.reproject) {
    auto t = Clock::now();
    if (dynamic && dynamic->rays) {
      std::vector<Bounds> boxes = dynamic_bounds(world);
      const float eps = options_.reprojection.epsilon * world.bounds.max_extent();
      st.forgotten = cache_.forget(moved_regions(dynamic_boxes_, boxes, radius + eps));
      dynamic_boxes_ = std::move(boxes);
    }
    const float eps = options_.reprojection.epsilon * world.bounds.max_extent();
    cache_.reproject(g, eps, compute_, &st.reprojection);
    st.reproject_s = since(t);
    t = Clock::now();
    visibility_.resize(g.size());
    st.ssao_pixels = ssao(g, options_.ssao_params, radius, frame_, visibility_, &compute_);
    st.ssao_s = since(t);
    t = Clock::now();
    cache_.resolve(g, visibility_);
    st.reproject_s += since(t);
  } else {
    // Without a history there is nothing to accumulate: the same pattern every frame (no
    // flicker from frame to frame).
    auto t = Clock::now();
    st.ssao_pixels = ssao(g, options_.ssao_params, radius, 0, visibility_);
    st.ssao_s = since(t);
  }
  auto t = Clock::now();
  ImageRGB image = resolve_frame(g, visibility_);
  st.resolve_s = since(t);
  st.total_s = since(start);
  ++frame_;
  return image;
}

}  // namespace irradcast
