#include "gpu_bvh.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "irradcast/common/error.h"

namespace irradcast {
namespace {

// Embree's builder calls these to make its nodes; they live in its thread-local allocator until
// the BVH is released, so they are plain structs.
struct BuildNode {
  bool leaf;
};
struct BuildInner : BuildNode {
  RTCBounds bounds[2];
  const BuildNode* children[2];
};
struct BuildLeaf : BuildNode {
  RTCBounds bounds;
  std::uint32_t count;
  std::uint32_t first;  // first of `count` entries in the leaf's own id array, right after it
};

void* create_node(RTCThreadLocalAllocator alloc, unsigned int, void*) {
  auto* n = new (rtcThreadLocalAlloc(alloc, sizeof(BuildInner), 16)) BuildInner;
  n->leaf = false;
  n->children[0] = n->children[1] = nullptr;
  return n;
}

void set_children(void* node, void** children, unsigned int count, void*) {
  auto* n = static_cast<BuildInner*>(node);
  for (unsigned k = 0; k < 2; ++k)
    n->children[k] = k < count ? static_cast<const BuildNode*>(children[k]) : nullptr;
}

void set_bounds(void* node, const RTCBounds** bounds, unsigned int count, void*) {
  auto* n = static_cast<BuildInner*>(node);
  for (unsigned k = 0; k < 2 && k < count; ++k) n->bounds[k] = *bounds[k];
}

void* create_leaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count,
                  void*) {
  void* mem = rtcThreadLocalAlloc(alloc, sizeof(BuildLeaf) + count * sizeof(std::uint32_t), 16);
  auto* leaf = new (mem) BuildLeaf;
  leaf->leaf = true;
  leaf->count = static_cast<std::uint32_t>(count);
  auto* ids = reinterpret_cast<std::uint32_t*>(leaf + 1);
  RTCBounds b{};
  b.lower_x = b.lower_y = b.lower_z = std::numeric_limits<float>::max();
  b.upper_x = b.upper_y = b.upper_z = -std::numeric_limits<float>::max();
  for (size_t i = 0; i < count; ++i) {
    ids[i] = prims[i].primID;
    b.lower_x = std::min(b.lower_x, prims[i].lower_x);
    b.lower_y = std::min(b.lower_y, prims[i].lower_y);
    b.lower_z = std::min(b.lower_z, prims[i].lower_z);
    b.upper_x = std::max(b.upper_x, prims[i].upper_x);
    b.upper_y = std::max(b.upper_y, prims[i].upper_y);
    b.upper_z = std::max(b.upper_z, prims[i].upper_z);
  }
  leaf->bounds = b;
  return leaf;
}

struct Flattener {
  const std::vector<GpuTriangle>& source;  // indexed by primID
  GpuBvh& out;

  // Appends a leaf's triangles; returns (first, count).
  std::pair<std::uint32_t, std::uint32_t> leaf(const BuildLeaf* l) {
    const auto* ids = reinterpret_cast<const std::uint32_t*>(l + 1);
    auto first = static_cast<std::uint32_t>(out.triangles.size());
    for (std::uint32_t i = 0; i < l->count; ++i) out.triangles.push_back(source[ids[i]]);
    return {first, l->count};
  }

  // Writes inner node `n` (and everything below it); returns its index.
  std::uint32_t inner(const BuildInner* n, int depth) {
    out.depth = std::max(out.depth, depth);
    auto index = static_cast<std::uint32_t>(out.nodes.size());
    out.nodes.emplace_back();
    std::uint32_t child[2] = {kEmptyChild, kEmptyChild}, count[2] = {kEmptyChild, kEmptyChild};
    glm::vec3 lo[2], hi[2];
    for (int k = 0; k < 2; ++k) {
      const BuildNode* c = n->children[k];
      lo[k] = glm::vec3(1.0f);
      hi[k] = glm::vec3(-1.0f);
      if (!c) continue;
      const RTCBounds& b = n->bounds[k];
      lo[k] = glm::vec3(b.lower_x, b.lower_y, b.lower_z);
      hi[k] = glm::vec3(b.upper_x, b.upper_y, b.upper_z);
      if (c->leaf) {
        std::tie(child[k], count[k]) = leaf(static_cast<const BuildLeaf*>(c));
      } else {
        child[k] = inner(static_cast<const BuildInner*>(c), depth + 1);
        count[k] = 0;
      }
    }
    GpuBvhNode& node = out.nodes[index];
    node.lo0 = lo[0];
    node.hi0 = hi[0];
    node.child0 = child[0];
    node.count0 = count[0];
    node.lo1 = lo[1];
    node.hi1 = hi[1];
    node.child1 = child[1];
    node.count1 = count[1];
    return index;
  }
};

bool hit_box(glm::vec3 lo, glm::vec3 hi, glm::vec3 o, glm::vec3 inv, float tmin, float tmax,
             float& tnear) {
  glm::vec3 t0 = (lo - o) * inv, t1 = (hi - o) * inv;
  glm::vec3 tn = glm::min(t0, t1), tf = glm::max(t0, t1) * 1.0000025f;  // conservative
  tnear = std::max(std::max(tn.x, tn.y), std::max(tn.z, tmin));
  float tfar = std::min(std::min(tf.x, tf.y), std::min(tf.z, tmax));
  return tnear <= tfar;
}

// shaders/common.glsl's watertight test, line for line.
struct ShearedRay {
  glm::vec3 o;
  int kx, ky, kz;
  glm::vec3 s;
};

ShearedRay shear(glm::vec3 o, glm::vec3 d) {
  ShearedRay r;
  r.o = o;
  glm::vec3 a = glm::abs(d);
  r.kz = a.x > a.y ? (a.x > a.z ? 0 : 2) : (a.y > a.z ? 1 : 2);
  r.kx = (r.kz + 1) % 3;
  r.ky = (r.kx + 1) % 3;
  if (d[r.kz] < 0.0f) std::swap(r.kx, r.ky);
  r.s = glm::vec3(d[r.kx] / d[r.kz], d[r.ky] / d[r.kz], 1.0f / d[r.kz]);
  return r;
}

bool hit_triangle(const GpuTriangle& tri, const ShearedRay& r, float tmin, float tmax,
                  glm::vec3& tuv) {
  const glm::vec3 a = tri.v0 - r.o, b = tri.v1 - r.o, c = tri.v2 - r.o;
  const float ax = a[r.kx] - r.s.x * a[r.kz], ay = a[r.ky] - r.s.y * a[r.kz];
  const float bx = b[r.kx] - r.s.x * b[r.kz], by = b[r.ky] - r.s.y * b[r.kz];
  const float cx = c[r.kx] - r.s.x * c[r.kz], cy = c[r.ky] - r.s.y * c[r.kz];
  const float u = cx * by - cy * bx, v = ax * cy - ay * cx, w = bx * ay - by * ax;
  if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
  const float det = u + v + w;
  if (det == 0.0f) return false;
  const float t = (u * a[r.kz] + v * b[r.kz] + w * c[r.kz]) * r.s.z / det;
  if (!(t > tmin && t < tmax)) return false;
  tuv = glm::vec3(t, v / det, w / det);
  return true;
}

// The static scene's triangles, and their bounds as Embree's builder takes them (primID: the
// index into `source`).
void collect_triangles(const World& world, std::vector<GpuTriangle>& source,
                       std::vector<RTCBuildPrimitive>& prims) {
  for (const WorldObject& o : world.objects) {
    if (!o.in_static_scene()) continue;  // hidden by an edit, or dynamic: rays pass through
    const auto& tris = o.triangles();
    for (std::uint32_t t = 0; t < tris.size(); ++t) {
      glm::vec3 a = o.positions[tris[t].x], b = o.positions[tris[t].y], c = o.positions[tris[t].z];
      GpuTriangle g;
      g.v0 = a;
      g.v1 = b;
      g.v2 = c;
      g.object = static_cast<std::uint32_t>(o.object);
      g.triangle = t;
      g.cut_out = world.material(o.object, t).cut_out() ? 1u : 0u;
      glm::vec3 lo = glm::min(a, glm::min(b, c)), hi = glm::max(a, glm::max(b, c));
      RTCBuildPrimitive p{};
      p.lower_x = lo.x;
      p.lower_y = lo.y;
      p.lower_z = lo.z;
      p.upper_x = hi.x;
      p.upper_y = hi.y;
      p.upper_z = hi.z;
      p.geomID = 0;
      p.primID = static_cast<unsigned>(source.size());
      source.push_back(g);
      prims.push_back(p);
    }
  }
}

}  // namespace

GpuBvh build_gpu_bvh(const World& world) {
  std::vector<GpuTriangle> source;
  std::vector<RTCBuildPrimitive> prims;
  collect_triangles(world, source, prims);
  GpuBvh out;
  if (prims.empty()) {  // one node, no children: every ray misses
    GpuBvhNode n{};
    n.child0 = n.child1 = n.count0 = n.count1 = kEmptyChild;
    n.lo0 = n.lo1 = glm::vec3(1.0f);
    n.hi0 = n.hi1 = glm::vec3(-1.0f);
    out.nodes.push_back(n);
    out.depth = 1;
    return out;
  }

  RTCDevice device = rtcNewDevice(nullptr);
  if (!device) throw Error("GPU BVH: cannot create an Embree device");
  RTCBVH bvh = rtcNewBVH(device);
  RTCBuildArguments args = rtcDefaultBuildArguments();
  args.buildQuality = RTC_BUILD_QUALITY_MEDIUM;
  args.maxBranchingFactor = 2;
  args.maxDepth = 40;
  args.minLeafSize = 1;
  args.maxLeafSize = 4;
  args.traversalCost = 1.0f;
  args.intersectionCost = 1.0f;
  args.bvh = bvh;
  args.primitives = prims.data();
  args.primitiveCount = prims.size();
  args.primitiveArrayCapacity = prims.size();
  args.createNode = create_node;
  args.setNodeChildren = set_children;
  args.setNodeBounds = set_bounds;
  args.createLeaf = create_leaf;
  void* root = rtcBuildBVH(&args);
  if (!root) {
    RTCError e = rtcGetDeviceError(device);
    rtcReleaseBVH(bvh);
    rtcReleaseDevice(device);
    throw Error("GPU BVH: rtcBuildBVH failed (Embree error " + std::to_string(static_cast<int>(e)) +
                ")");
  }
  Flattener f{source, out};
  out.nodes.reserve(prims.size());
  out.triangles.reserve(prims.size());
  const auto* r = static_cast<const BuildNode*>(root);
  if (r->leaf) {  // the root must be an inner node: wrap a single leaf
    BuildInner wrap;
    wrap.leaf = false;
    wrap.bounds[0] = static_cast<const BuildLeaf*>(r)->bounds;
    wrap.children[0] = r;
    wrap.children[1] = nullptr;
    f.inner(&wrap, 1);
  } else {
    f.inner(static_cast<const BuildInner*>(r), 1);
  }
  rtcReleaseBVH(bvh);
  rtcReleaseDevice(device);
  return out;
}

Hit GpuBvh::intersect(const Ray& ray) const {
  Hit h;
  float tmax = ray.tmax;
  const glm::vec3 o = ray.origin, d = ray.direction;
  auto safe = [](float x) {
    const float tiny = 1e-20f;
    return std::fabs(x) < tiny ? (x < 0.0f ? -tiny : tiny) : x;
  };
  const glm::vec3 inv = 1.0f / glm::vec3(safe(d.x), safe(d.y), safe(d.z));
  const ShearedRay sheared = shear(o, d);
  std::uint32_t stack[48];
  int sp = 0;
  std::uint32_t node = 0;
  while (true) {
    const GpuBvhNode& n = nodes[node];
    std::uint32_t child[2] = {n.child0, n.child1}, count[2] = {n.count0, n.count1};
    float tn[2] = {0.0f, 0.0f};
    bool hit[2];
    hit[0] = count[0] != kEmptyChild && hit_box(n.lo0, n.hi0, o, inv, ray.tmin, tmax, tn[0]);
    hit[1] = count[1] != kEmptyChild && hit_box(n.lo1, n.hi1, o, inv, ray.tmin, tmax, tn[1]);
    for (int k = 0; k < 2; ++k) {
      if (!hit[k] || count[k] == 0) continue;
      hit[k] = false;
      for (std::uint32_t i = child[k]; i < child[k] + count[k]; ++i) {
        glm::vec3 tuv;
        if (hit_triangle(triangles[i], sheared, ray.tmin, tmax, tuv)) {
          h.object = static_cast<int>(triangles[i].object);
          h.triangle = triangles[i].triangle;
          h.t = tmax = tuv.x;
          h.u = tuv.y;
          h.v = tuv.z;
        }
      }
    }
    if (hit[0] && hit[1]) {
      bool first = tn[0] <= tn[1];
      if (sp < 48) stack[sp++] = first ? child[1] : child[0];
      node = first ? child[0] : child[1];
    } else if (hit[0]) {
      node = child[0];
    } else if (hit[1]) {
      node = child[1];
    } else {
      if (sp == 0) break;
      node = stack[--sp];
    }
  }
  return h;
}

}  // namespace irradcast
