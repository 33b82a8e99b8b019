// The Embree scene (ray_scene.h). Cut-outs: an object with Mask materials (cutout.h) gets Embree
// intersection and occlusion filter functions that reject hits on its cut-out points, so every
// ray, occlusion ray and packet passes through the holes, in the single-level and the two-level
// (editable) scene alike. Objects without Mask materials get no filter: an opaque scene traces
// exactly as before.
#include "irradcast/common/ray_scene.h"

#include <embree3/rtcore.h>

#include <cstring>
#include <string>

#include "irradcast/common/cutout.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"

namespace irradcast {
namespace {

void embree_error(void*, RTCError code, const char* str) {
  if (code == RTC_ERROR_NONE) return;
  log::error("embree", "error " + std::to_string(static_cast<int>(code)) + ": " + (str ? str : ""));
}

RTCDevice shared_device() {
  static RTCDevice device = [] {
    RTCDevice d = rtcNewDevice(nullptr);
    if (!d)
      throw Error("cannot create an Embree device (error " +
                  std::to_string(static_cast<int>(rtcGetDeviceError(nullptr))) + ")");
    rtcSetDeviceErrorFunction(d, embree_error, nullptr);
    return d;
  }();
  return device;
}

Hit to_hit(const RTCRayHit& rh) {
  Hit h;
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return h;
  h.object = static_cast<int>(rh.hit.geomID);
  h.triangle = rh.hit.primID;
  h.u = rh.hit.u;
  h.v = rh.hit.v;
  h.t = rh.ray.tfar;
  return h;
}

void fill_ray(RTCRay& r, const Ray& ray) {
  r.org_x = ray.origin.x;
  r.org_y = ray.origin.y;
  r.org_z = ray.origin.z;
  r.dir_x = ray.direction.x;
  r.dir_y = ray.direction.y;
  r.dir_z = ray.direction.z;
  r.tnear = ray.tmin;
  r.tfar = ray.tmax;
  r.time = 0.0f;
  r.mask = 0xFFFFFFFFu;
  r.id = 0;
  r.flags = 0;
}

// What the filter of an object with Mask materials needs to test a hit.
struct CutOutFilter {
  const World* world = nullptr;
  int object = -1;
};

// Intersection and occlusion filter of such an object: rejects every candidate hit whose point
// is cut out, so Embree goes on to the next surface along the ray. Called for single rays and
// packets alike (N lanes, valid[i] == -1 for the active ones).
void cut_out_filter(const RTCFilterFunctionNArguments* args) {
  const auto* f = static_cast<const CutOutFilter*>(args->geometryUserPtr);
  const unsigned n = args->N;
  for (unsigned i = 0; i < n; ++i) {
    if (args->valid[i] != -1) continue;
    if (cut_out(*f->world, f->object, RTCHitN_primID(args->hit, n, i), RTCHitN_u(args->hit, n, i),
                RTCHitN_v(args->hit, n, i)))
      args->valid[i] = 0;
  }
}

// Makes Embree skip the cut-out points of object `object` (its filter's data: `f`, which must
// outlive the geometry).
void attach_cut_out_filter(RTCGeometry geom, const World& world, int object, CutOutFilter& f) {
  if (!rtcGetDeviceProperty(shared_device(), RTC_DEVICE_PROPERTY_FILTER_FUNCTION_SUPPORTED)) {
    rtcReleaseGeometry(geom);
    throw Error(
        "the scene has cut-out (alphaMode MASK) materials, but this Embree library was "
        "built without filter functions");
  }
  f.world = &world;
  f.object = object;
  rtcSetGeometryUserData(geom, &f);
  rtcSetGeometryIntersectFilterFunction(geom, cut_out_filter);
  rtcSetGeometryOccludedFilterFunction(geom, cut_out_filter);
}

}  // namespace

struct RayScene::Impl {
  RTCScene scene = nullptr;
  std::vector<RTCGeometry> geometries;  // per object, retained
  // Per object with Mask materials, the user data of its filter (sized once: Embree keeps
  // pointers into it).
  std::vector<CutOutFilter> filters;
  bool editable = false;
  // Whether Embree runs 16-wide packets natively here (AVX-512): intersect(RayBatch&) then traces
  // in packets of 16, else one ray at a time (the same hits either way).
  bool packets16 = __builtin_cpu_supports("avx512f");
};

RayScene::RayScene(const World& world, bool editable, RaySceneContent content)
    : impl_(std::make_unique<Impl>()), world_(&world) {
  const bool dynamic = content == RaySceneContent::Dynamic;
  editable = editable || dynamic;
  float extent = world.bounds.max_extent();
  epsilon_ = 1e-4f * (extent > 0.0f ? extent : 1.0f);
  RTCDevice device = shared_device();
  impl_->editable = editable;
  impl_->scene = rtcNewScene(device);
  if (editable) {
    // Two-level: per-geometry BVHs (built at HIGH quality) under a top level rebuilt per commit.
    rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_LOW);
    rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST | RTC_SCENE_FLAG_DYNAMIC);
  } else {
    rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
    rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  }
  impl_->filters.resize(world.objects.size());
  for (const WorldObject& o : world.objects) {
    if (o.dynamic != dynamic) {  // not in this scene: not even a disabled geometry (the static
      impl_->geometries.push_back(nullptr);  // BVH is the one of the scene without the object)
      continue;
    }
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (editable) rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), o.positions.size()));
    const auto& tris = o.triangles();
    auto* ib = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), tris.size()));
    if (!vb || !ib) {
      rtcReleaseGeometry(geom);
      throw Error("Embree could not allocate buffers for object " + std::to_string(o.object));
    }
    std::memcpy(vb, o.positions.data(), o.positions.size() * sizeof(glm::vec3));
    std::memcpy(ib, tris.data(), tris.size() * sizeof(glm::uvec3));
    if (has_cut_outs(world, o.object))
      attach_cut_out_filter(geom, world, o.object,
                            impl_->filters[static_cast<std::size_t>(o.object)]);
    if (!o.visible) rtcDisableGeometry(geom);
    rtcCommitGeometry(geom);
    rtcAttachGeometryByID(impl_->scene, geom, static_cast<unsigned>(o.object));
    impl_->geometries.push_back(geom);  // keeps our reference for update()
  }
  rtcCommitScene(impl_->scene);
}

RayScene::~RayScene() {
  if (!impl_) return;
  for (RTCGeometry g : impl_->geometries)
    if (g) rtcReleaseGeometry(g);
  if (impl_->scene) rtcReleaseScene(impl_->scene);
}

bool RayScene::editable() const {
  return impl_->editable;
}

void RayScene::update(const std::vector<int>& objects) {
  if (objects.empty()) return;
  for (int index : objects) {
    if (index < 0 || static_cast<std::size_t>(index) >= impl_->geometries.size())
      throw Error("ray scene: no object " + std::to_string(index) + " to update");
    const WorldObject& o = world_->objects[static_cast<std::size_t>(index)];
    RTCGeometry geom = impl_->geometries[static_cast<std::size_t>(index)];
    if (!geom) continue;  // not in this scene
    auto* vb = static_cast<float*>(rtcGetGeometryBufferData(geom, RTC_BUFFER_TYPE_VERTEX, 0));
    if (!vb) throw Error("ray scene: object " + std::to_string(index) + " has no vertex buffer");
    std::memcpy(vb, o.positions.data(), o.positions.size() * sizeof(glm::vec3));
    // The object's BVH keeps its shape and gets new boxes (a rigid motion moves every triangle
    // with it); the top level is rebuilt by the scene commit.
    if (impl_->editable) rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_REFIT);
    rtcUpdateGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0);
    if (o.visible)
      rtcEnableGeometry(geom);
    else
      rtcDisableGeometry(geom);
    rtcCommitGeometry(geom);
  }
  rtcCommitScene(impl_->scene);
}

RTCScene RayScene::embree_scene() const {
  return impl_->scene;
}

Hit RayScene::intersect(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  fill_ray(rh.ray, ray);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx, &rh);
  return to_hit(rh);
}

namespace {

// Lane l of an Embree ray packet (RTCRay8 / RTCRay16): from o along d over [tmin, tmax].
template <typename RayN>
void set_lane(RayN& r, int l, glm::vec3 o, glm::vec3 d, float tmin, float tmax, unsigned id) {
  r.org_x[l] = o.x;
  r.org_y[l] = o.y;
  r.org_z[l] = o.z;
  r.tnear[l] = tmin;
  r.dir_x[l] = d.x;
  r.dir_y[l] = d.y;
  r.dir_z[l] = d.z;
  r.time[l] = 0.0f;
  r.tfar[l] = tmax;
  r.mask[l] = 0xFFFFFFFFu;
  r.id[l] = id;
  r.flags[l] = 0;
}

// Lane l of a traced ray/hit packet (RTCRayHit8 / RTCRayHit16) as a Hit.
template <typename RayHitN>
Hit lane_hit(const RayHitN& rh, int l) {
  Hit h;
  if (rh.hit.geomID[l] == RTC_INVALID_GEOMETRY_ID) return h;
  h.object = static_cast<int>(rh.hit.geomID[l]);
  h.triangle = rh.hit.primID[l];
  h.u = rh.hit.u[l];
  h.v = rh.hit.v[l];
  h.t = rh.ray.tfar[l];
  return h;
}

// Rays first .. first + 16 of b (those below b.count) as one Embree packet.
void intersect16(RTCScene scene, RTCIntersectContext& ctx, RayBatch& b, int first) {
  alignas(64) int valid[16];
  alignas(64) RTCRayHit16 rh;
  for (int l = 0; l < 16; ++l) {
    const int i = first + l < b.count ? first + l : first;
    valid[l] = first + l < b.count ? -1 : 0;
    set_lane(rh.ray, l, glm::vec3(b.ox[i], b.oy[i], b.oz[i]), glm::vec3(b.dx[i], b.dy[i], b.dz[i]),
             0.0f, b.tmax, 0u);
    rh.hit.geomID[l] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][l] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect16(valid, scene, &ctx, &rh);
  for (int l = 0; l < 16 && first + l < b.count; ++l) b.hit[first + l] = lane_hit(rh, l);
}

}  // namespace

void RayScene::intersect(RayBatch& b) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (impl_->packets16) {
    for (int first = 0; first < b.count; first += 16) intersect16(impl_->scene, ctx, b, first);
    return;
  }
  for (int i = 0; i < b.count; ++i) {
    RTCRayHit rh;
    rh.ray.org_x = b.ox[i];
    rh.ray.org_y = b.oy[i];
    rh.ray.org_z = b.oz[i];
    rh.ray.tnear = 0.0f;
    rh.ray.dir_x = b.dx[i];
    rh.ray.dir_y = b.dy[i];
    rh.ray.dir_z = b.dz[i];
    rh.ray.time = 0.0f;
    rh.ray.tfar = b.tmax;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(impl_->scene, &ctx, &rh);
    b.hit[i] = to_hit(rh);
  }
}

bool RayScene::occluded(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r;
  fill_ray(r, ray);
  rtcOccluded1(impl_->scene, &ctx, &r);
  return r.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

void RayScene::intersect8(const Ray* rays, int count, Hit* hits) const {
  alignas(32) int valid[8];
  alignas(32) RTCRayHit8 rh;
  for (int i = 0; i < 8; ++i) {
    const Ray& r = rays[i < count ? i : 0];
    valid[i] = i < count ? -1 : 0;
    set_lane(rh.ray, i, r.origin, r.direction, r.tmin, r.tmax, static_cast<unsigned>(i));
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect8(valid, impl_->scene, &ctx, &rh);
  for (int i = 0; i < count; ++i) hits[i] = lane_hit(rh, i);
}

void RayScene::occluded8(const Ray* rays, int count, bool* blocked) const {
  alignas(32) int valid[8];
  alignas(32) RTCRay8 r;
  for (int i = 0; i < 8; ++i) {
    const Ray& ray = rays[i < count ? i : 0];
    valid[i] = i < count ? -1 : 0;
    set_lane(r, i, ray.origin, ray.direction, ray.tmin, ray.tmax, static_cast<unsigned>(i));
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcOccluded8(valid, impl_->scene, &ctx, &r);
  for (int i = 0; i < count; ++i) blocked[i] = r.tfar[i] < 0.0f;  // -inf on a hit
}

}  // namespace irradcast
