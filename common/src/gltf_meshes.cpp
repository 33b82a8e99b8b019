// glTF import: meshes. Each glTF mesh becomes one Scene mesh: its triangle primitives (lists,
// strips, fans; points and lines are skipped with a warning) share vertex blocks when they use
// the same attribute accessors, and the blocks are merged, with attributes some blocks lack
// filled in (zero UVs, smooth normals).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "gltf_import.h"

namespace irradcast::gltf_import {

namespace {

// The vertices of one primitive (or several primitives sharing the same attribute accessors).
struct Block {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // empty = compute
  std::vector<glm::vec2> uv0, uv1;
};

// POSITION, NORMAL, TEXCOORD_0 and TEXCOORD_1 accessors (-1 = absent).
using BlockKey = std::tuple<int, int, int, int>;

const AccessorKind kVec3Float{TINYGLTF_TYPE_VEC3, 3, {TINYGLTF_COMPONENT_TYPE_FLOAT}, false};
const AccessorKind kTexcoord{TINYGLTF_TYPE_VEC2,
                             2,
                             {TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                              TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT},
                             true};
const AccessorKind kIndices{
    TINYGLTF_TYPE_SCALAR,
    1,
    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
     TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT},
    false};

// Smooth vertex normals of the merged mesh (area-weighted face normals; +Z where they cancel).
std::vector<glm::vec3> smooth_normals(const Mesh& mesh, std::size_t vertex_total) {
  std::vector<glm::vec3> computed(vertex_total, glm::vec3(0.0f));
  for (const glm::uvec3& t : mesh.triangles) {
    glm::vec3 n = glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                             mesh.positions[t.z] - mesh.positions[t.x]);
    computed[t.x] += n;
    computed[t.y] += n;
    computed[t.z] += n;
  }
  for (glm::vec3& n : computed) {
    float len = glm::length(n);
    n = len > 0.0f && std::isfinite(len) ? n / len : glm::vec3(0.0f, 0.0f, 1.0f);
  }
  return computed;
}

}  // namespace

// The vertex blocks of one mesh being converted.
struct MeshBlocks {
  std::vector<Block> blocks;
  std::vector<std::size_t> base;  // first vertex of each block in the merged mesh
  std::size_t vertex_total = 0;
  std::map<BlockKey, std::size_t> of;  // attribute accessors -> block

  // Concatenates the blocks' vertices into `mesh` (which has its triangles).
  void merge_into(Mesh& mesh) const;
};

void MeshBlocks::merge_into(Mesh& mesh) const {
  bool any_normals = false, missing_normals = false, any_uv0 = false, any_uv1 = false;
  for (const Block& bl : blocks) {
    (bl.normals.empty() ? missing_normals : any_normals) = true;
    any_uv0 |= !bl.uv0.empty();
    any_uv1 |= !bl.uv1.empty();
  }
  mesh.positions.reserve(vertex_total);
  for (const Block& bl : blocks)
    mesh.positions.insert(mesh.positions.end(), bl.positions.begin(), bl.positions.end());
  auto merge = [&](bool any, std::vector<glm::vec2> Block::*member, std::vector<glm::vec2>& dst) {
    if (!any) return;
    dst.reserve(vertex_total);
    for (const Block& bl : blocks) {
      const auto& src = bl.*member;
      if (src.empty())
        dst.insert(dst.end(), bl.positions.size(), glm::vec2(0.0f));
      else
        dst.insert(dst.end(), src.begin(), src.end());
    }
  };
  merge(any_uv0, &Block::uv0, mesh.uv0);
  merge(any_uv1, &Block::uv1, mesh.uv1);
  if (!any_normals) return;
  std::vector<glm::vec3> computed;
  if (missing_normals) computed = smooth_normals(mesh, vertex_total);
  mesh.normals.reserve(vertex_total);
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const Block& bl = blocks[b];
    if (bl.normals.empty())
      mesh.normals.insert(mesh.normals.end(), computed.begin() + base[b],
                          computed.begin() + base[b] + bl.positions.size());
    else
      mesh.normals.insert(mesh.normals.end(), bl.normals.begin(), bl.normals.end());
  }
}

void Loader::convert_meshes(Scene& scene) {
  for (std::size_t i = 0; i < m_.meshes.size(); ++i) convert_mesh(static_cast<int>(i), scene);
}

void Loader::convert_mesh(int index, Scene& scene) {
  const tinygltf::Mesh& gm = m_.meshes[index];
  const std::string label = "mesh " + std::to_string(index) + quoted(gm.name);
  Mesh mesh;
  mesh.name = gm.name;
  MeshBlocks blocks;
  for (std::size_t p = 0; p < gm.primitives.size(); ++p) {
    const tinygltf::Primitive& prim = gm.primitives[p];
    const std::string what = label + " primitive " + std::to_string(p);
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode == TINYGLTF_MODE_POINTS || mode == TINYGLTF_MODE_LINE ||
        mode == TINYGLTF_MODE_LINE_LOOP || mode == TINYGLTF_MODE_LINE_STRIP) {
      static const char* names[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
      warn(what + " has mode " + names[mode] + "; only triangles are supported, it is skipped");
      continue;
    }
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN)
      fail(what + " has an unknown mode " + std::to_string(mode));
    const std::size_t b = primitive_block(prim, what, label, blocks);
    const std::size_t n = blocks.blocks[b].positions.size();
    const std::uint32_t base = static_cast<std::uint32_t>(blocks.base[b]);
    const std::vector<std::uint32_t> idx = primitive_indices(prim, what, n);
    const int material = primitive_material(prim, what, scene);
    emit_triangles(mode, idx, base, material, what, mesh);
  }
  if (!mesh.triangles.empty())
    blocks.merge_into(mesh);
  else if (!gm.primitives.empty())
    warn(label + " has no triangles; nodes using it get no mesh");
  scene.meshes.push_back(std::move(mesh));
}

// The block holding the primitive's vertices: one read before by a primitive with the same
// attribute accessors, or a new one read and validated now.
std::size_t Loader::primitive_block(const tinygltf::Primitive& prim, const std::string& what,
                                    const std::string& mesh_label, MeshBlocks& blocks) {
  auto attr = [&](const char* key) {
    auto it = prim.attributes.find(key);
    return it == prim.attributes.end() ? -1 : it->second;
  };
  const int pos_acc = attr("POSITION");
  if (pos_acc < 0) fail(what + " has no POSITION attribute");
  const BlockKey key(pos_acc, attr("NORMAL"), attr("TEXCOORD_0"), attr("TEXCOORD_1"));
  auto found = blocks.of.find(key);
  if (found != blocks.of.end()) return found->second;

  Block block;
  std::vector<float> pos = read_accessor<float>(pos_acc, what + " POSITION", kVec3Float);
  const std::size_t n = pos.size() / 3;
  for (float f : pos)
    if (!std::isfinite(f)) fail(what + " has non-finite (NaN or infinite) POSITION values");
  block.positions.resize(n);
  for (std::size_t v = 0; v < n; ++v)
    block.positions[v] = glm::vec3(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2]);
  auto check_count = [&](std::size_t got, const char* name) {
    if (got != n)
      fail(what + " attribute " + name + " has " + std::to_string(got) +
           " elements but POSITION has " + std::to_string(n));
  };
  if (std::get<1>(key) >= 0) {
    std::vector<float> nrm = read_accessor<float>(std::get<1>(key), what + " NORMAL", kVec3Float);
    check_count(nrm.size() / 3, "NORMAL");
    bool finite = std::all_of(nrm.begin(), nrm.end(), [](float f) { return std::isfinite(f); });
    if (!finite) {
      warn(what + " has non-finite NORMAL values; normals are recomputed");
    } else {
      block.normals.resize(n);
      for (std::size_t v = 0; v < n; ++v)
        block.normals[v] = glm::vec3(nrm[3 * v], nrm[3 * v + 1], nrm[3 * v + 2]);
    }
  }
  auto read_uv = [&](int acc, const char* name, std::vector<glm::vec2>& dst) {
    if (acc < 0) return;
    std::vector<float> uv = read_accessor<float>(acc, what + " " + name, kTexcoord);
    check_count(uv.size() / 2, name);
    bool finite = std::all_of(uv.begin(), uv.end(), [](float f) { return std::isfinite(f); });
    if (!finite) {
      warn(what + " has non-finite " + name + " values; they are set to 0");
      for (float& f : uv)
        if (!std::isfinite(f)) f = 0.0f;
    }
    dst.resize(n);
    for (std::size_t v = 0; v < n; ++v) dst[v] = glm::vec2(uv[2 * v], uv[2 * v + 1]);
  };
  read_uv(std::get<2>(key), "TEXCOORD_0", block.uv0);
  read_uv(std::get<3>(key), "TEXCOORD_1", block.uv1);
  if (!fits(blocks.vertex_total, n, std::numeric_limits<std::uint32_t>::max()))
    fail(mesh_label + " has too many vertices");
  const std::size_t b = blocks.blocks.size();
  blocks.of[key] = b;
  blocks.base.push_back(blocks.vertex_total);
  blocks.vertex_total += n;
  blocks.blocks.push_back(std::move(block));
  return b;
}

// The primitive's indices (each checked against its n vertices), or 0 .. n-1 without any.
std::vector<std::uint32_t> Loader::primitive_indices(const tinygltf::Primitive& prim,
                                                     const std::string& what, std::size_t n) {
  std::vector<std::uint32_t> idx;
  if (prim.indices >= 0) {
    idx = read_accessor<std::uint32_t>(prim.indices, what + " indices", kIndices);
    for (std::size_t k = 0; k < idx.size(); ++k)
      if (idx[k] >= n)
        fail(what + " index " + std::to_string(idx[k]) + " (at position " + std::to_string(k) +
             ") is out of range: the primitive has " + std::to_string(n) + " vertices");
  } else {
    idx.resize(n);
    for (std::size_t k = 0; k < n; ++k) idx[k] = static_cast<std::uint32_t>(k);
  }
  return idx;
}

int Loader::primitive_material(const tinygltf::Primitive& prim, const std::string& what,
                               Scene& scene) {
  if (prim.material < 0) return default_material(scene);
  if (static_cast<std::size_t>(prim.material) >= m_.materials.size())
    fail(what + " refers to material " + std::to_string(prim.material) + ", which does not exist");
  return prim.material;
}

// Appends the primitive's triangles (list, strip or fan; strips and fans drop triangles with a
// repeated index) to `mesh`, their vertices offset by `base`.
void Loader::emit_triangles(int mode, const std::vector<std::uint32_t>& idx, std::uint32_t base,
                            int material, const std::string& what, Mesh& mesh) {
  auto emit = [&](std::uint32_t a, std::uint32_t b2, std::uint32_t c, bool drop_degenerate) {
    if (drop_degenerate && (a == b2 || b2 == c || a == c)) return;
    mesh.triangles.emplace_back(base + a, base + b2, base + c);
    mesh.triangle_material.push_back(static_cast<std::uint32_t>(material));
  };
  const std::size_t count = idx.size();
  if (mode == TINYGLTF_MODE_TRIANGLES) {
    if (count % 3 != 0)
      warn(what + " has " + std::to_string(count) +
           " indices, not a multiple of 3; the trailing ones are ignored");
    for (std::size_t k = 0; k + 2 < count; k += 3) emit(idx[k], idx[k + 1], idx[k + 2], false);
  } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    for (std::size_t k = 0; k + 2 < count; ++k) {
      if (k % 2 == 0)
        emit(idx[k], idx[k + 1], idx[k + 2], true);
      else
        emit(idx[k], idx[k + 2], idx[k + 1], true);
    }
  } else {  // fan
    for (std::size_t k = 0; k + 2 < count; ++k) emit(idx[k + 1], idx[k + 2], idx[0], true);
  }
}

}  // namespace irradcast::gltf_import
