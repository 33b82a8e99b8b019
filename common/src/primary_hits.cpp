#include "irradcast/common/primary_hits.h"

#include <embree3/rtcore.h>
#include <emmintrin.h>
#include <tbb/blocked_range2d.h>
#include <tbb/parallel_for.h>

#include <vector>

#include "irradcast/common/pinhole.h"

namespace irradcast {
namespace {

constexpr int kBw = PrimaryBlock::kWidth, kBh = PrimaryBlock::kHeight;

// A packet's rays with the fields that stay the same from packet to packet (origin, tnear,
// time, mask, id, flags) set once.
struct Packet {
  alignas(64) RTCRayHit16 rh;
  Packet(glm::vec3 origin) {
    for (int i = 0; i < 16; ++i) {
      rh.ray.org_x[i] = origin.x;
      rh.ray.org_y[i] = origin.y;
      rh.ray.org_z[i] = origin.z;
      rh.ray.tnear[i] = 0.0f;
      rh.ray.time[i] = 0.0f;
      rh.ray.mask[i] = 0xFFFFFFFFu;
      rh.ray.id[i] = static_cast<unsigned>(i);
      rh.ray.flags[i] = 0;
    }
  }
};

// The unit directions of the 4 lanes of one packet row: PinholeRays::direction (glm's
// normalize: v * (1 / sqrt(dot(v, v))), the same operations in the same order, so the same bits)
// at the image-plane offsets sx[0..3], sy.
void row_directions(const PinholeRays& pin, const float* sx, float sy, float* dx, float* dy,
                    float* dz) {
  const __m128 s = _mm_loadu_ps(sx), t = _mm_set1_ps(sy);
  const __m128 x =
      _mm_add_ps(_mm_add_ps(_mm_set1_ps(pin.forward.x), _mm_mul_ps(s, _mm_set1_ps(pin.right.x))),
                 _mm_mul_ps(t, _mm_set1_ps(pin.up.x)));
  const __m128 y =
      _mm_add_ps(_mm_add_ps(_mm_set1_ps(pin.forward.y), _mm_mul_ps(s, _mm_set1_ps(pin.right.y))),
                 _mm_mul_ps(t, _mm_set1_ps(pin.up.y)));
  const __m128 z =
      _mm_add_ps(_mm_add_ps(_mm_set1_ps(pin.forward.z), _mm_mul_ps(s, _mm_set1_ps(pin.right.z))),
                 _mm_mul_ps(t, _mm_set1_ps(pin.up.z)));
  const __m128 len2 = _mm_add_ps(_mm_add_ps(_mm_mul_ps(x, x), _mm_mul_ps(y, y)), _mm_mul_ps(z, z));
  const __m128 inv = _mm_div_ps(_mm_set1_ps(1.0f), _mm_sqrt_ps(len2));
  _mm_store_ps(dx, _mm_mul_ps(x, inv));
  _mm_store_ps(dy, _mm_mul_ps(y, inv));
  _mm_store_ps(dz, _mm_mul_ps(z, inv));
}

// The packet at pixel (b.x0, b.y0): its rays through Embree (one coherent rtcIntersect16), the
// hits copied into b as SoA; inactive lanes miss.
void trace_block(RTCScene scene, const PinholeRays& pin, const float* sx, const float* sy,
                 int width, int height, Packet& p, PrimaryBlock& b) {
  RTCRayHit16& rh = p.rh;
  for (int j = 0; j < kBh; ++j) {
    const int y = b.y0 + j;
    for (int i = 0; i < kBw; ++i) b.active[j * kBw + i] = b.x0 + i < width && y < height ? -1 : 0;
    row_directions(pin, sx + b.x0, sy[y], b.dir_x + j * kBw, b.dir_y + j * kBw, b.dir_z + j * kBw);
  }
  const float tmax = Ray{}.tmax;
  for (int i = 0; i < 16; ++i) {
    rh.ray.dir_x[i] = b.dir_x[i];
    rh.ray.dir_y[i] = b.dir_y[i];
    rh.ray.dir_z[i] = b.dir_z[i];
    rh.ray.tfar[i] = tmax;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect16(b.active, scene, &ctx, &rh);
  for (int i = 0; i < 16; ++i) {
    // RTC_INVALID_GEOMETRY_ID (~0u) reads as -1: a miss; Embree leaves inactive lanes alone.
    b.object[i] = static_cast<std::int32_t>(rh.hit.geomID[i]);
    b.triangle[i] = rh.hit.primID[i];
    b.u[i] = rh.hit.u[i];
    b.v[i] = rh.hit.v[i];
    b.t[i] = rh.ray.tfar[i];
  }
}

// The packets of one task's tile range, row by row, traced one at a time into the caller's block.
class TilePackets final : public PacketStream {
 public:
  TilePackets(RTCScene scene, const PinholeRays& pin, const float* sx, const float* sy, int width,
              int height, const tbb::blocked_range2d<int>& r)
      : scene_(scene),
        pin_(pin),
        sx_(sx),
        sy_(sy),
        width_(width),
        height_(height),
        r_(r),
        packet_(pin.eye),
        by_(r.rows().begin()),
        bx_(r.cols().begin()) {}
  bool next(PrimaryBlock& b) override {
    if (by_ >= r_.rows().end() || r_.cols().empty()) return false;
    b.origin = pin_.eye;
    b.x0 = bx_ * kBw;
    b.y0 = by_ * kBh;
    trace_block(scene_, pin_, sx_, sy_, width_, height_, packet_, b);
    if (++bx_ == r_.cols().end()) {
      bx_ = r_.cols().begin();
      ++by_;
    }
    return true;
  }

 private:
  RTCScene scene_;
  const PinholeRays& pin_;
  const float *sx_, *sy_;
  int width_, height_;
  const tbb::blocked_range2d<int>& r_;
  Packet packet_;
  int by_, bx_;
};

}  // namespace

void trace_primary_tiles(const RayScene& rays, const CameraPose& camera, int width, int height,
                         const std::function<void(PacketStream&)>& tile) {
  const PinholeRays pin(camera, width, height);
  const int bw = (width + kBw - 1) / kBw, bh = (height + kBh - 1) / kBh;
  // The image-plane offsets per column and per row (camera_ray's expressions, once each), padded
  // to whole packets.
  std::vector<float> sx(static_cast<std::size_t>(bw * kBw)), sy(static_cast<std::size_t>(bh * kBh));
  for (int x = 0; x < bw * kBw; ++x) sx[static_cast<std::size_t>(x)] = pin.sx(x + 0.5f);
  for (int y = 0; y < bh * kBh; ++y) sy[static_cast<std::size_t>(y)] = pin.sy(y + 0.5f);
  tbb::parallel_for(
      tbb::blocked_range2d<int>(0, bh, 2, 0, bw, 4), [&](const tbb::blocked_range2d<int>& r) {
        TilePackets packets(rays.embree_scene(), pin, sx.data(), sy.data(), width, height, r);
        tile(packets);
      });
}

void trace_primary_blocks(const RayScene& rays, const CameraPose& camera, int width, int height,
                          const std::function<void(const PrimaryBlock&)>& block) {
  trace_primary_tiles(rays, camera, width, height, [&](PacketStream& packets) {
    PrimaryBlock b;
    while (packets.next(b)) block(b);
  });
}

}  // namespace irradcast
