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
  dynamic_state_.clear();
}

std::vector<Bounds> ClientPasses::moved_dynamic_objects(const World& world, float margin) {
  std::vector<Bounds> regions;
  if (dynamic_state_.size() != world.objects.size())
    dynamic_state_.assign(world.objects.size(), {});
  const auto grown = [margin](Bounds b) {
    b.lo -= glm::vec3(margin);
    b.hi += glm::vec3(margin);
    return b;
  };
  for (std::size_t i = 0; i < world.objects.size(); ++i) {
    const WorldObject& o = world.objects[i];
    DynamicState& s = dynamic_state_[i];
    if (!o.dynamic || (s.known && s.visible == o.visible && s.transform == o.transform)) continue;
    if (s.known && s.visible) regions.push_back(grown(s.box));
    s = DynamicState{true, o.visible, o.transform, Bounds{}};
    if (o.visible) {
      for (const glm::vec3& p : o.positions) s.box.extend(p);
      regions.push_back(grown(s.box));
    }
  }
  return regions;
}

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
      const float eps = options_.reprojection.epsilon * world.bounds.max_extent();
      const std::vector<Bounds> regions = moved_dynamic_objects(world, radius + eps);
      if (regions.size() > kMaxForgetRegions)
        cache_.clear();  // many objects moved at once: cheaper to start again
      else
        st.forgotten = cache_.forget(regions);
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
