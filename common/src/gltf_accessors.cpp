// glTF import: accessors. Reads an accessor's elements (dense from its bufferView, zeros when it
// has none, then its sparse overrides) after checking its type, component type and every byte
// range against the buffers.
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "gltf_import.h"
#include "irradcast/common/code_names.h"

namespace irradcast::gltf_import {
namespace {

// Accessors without a bufferView (zeros, optionally overridden by sparse values) are allocated
// from their declared count alone: cap it so a hostile file cannot ask for gigabytes.
constexpr std::size_t kMaxUnbackedElements = std::size_t{1} << 24;

int component_size(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return 4;
    default:
      return 0;
  }
}

constexpr CodeName kComponentNames[] = {
    {TINYGLTF_COMPONENT_TYPE_BYTE, "BYTE"},
    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE, "UNSIGNED_BYTE"},
    {TINYGLTF_COMPONENT_TYPE_SHORT, "SHORT"},
    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, "UNSIGNED_SHORT"},
    {TINYGLTF_COMPONENT_TYPE_INT, "INT"},
    {TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, "UNSIGNED_INT"},
    {TINYGLTF_COMPONENT_TYPE_FLOAT, "FLOAT"},
    {TINYGLTF_COMPONENT_TYPE_DOUBLE, "DOUBLE"},
};

constexpr CodeName kTypeNames[] = {
    {TINYGLTF_TYPE_SCALAR, "SCALAR"}, {TINYGLTF_TYPE_VEC2, "VEC2"}, {TINYGLTF_TYPE_VEC3, "VEC3"},
    {TINYGLTF_TYPE_VEC4, "VEC4"},     {TINYGLTF_TYPE_MAT2, "MAT2"}, {TINYGLTF_TYPE_MAT3, "MAT3"},
    {TINYGLTF_TYPE_MAT4, "MAT4"},
};

const char* component_name(int component_type) {
  return code_name(component_type, kComponentNames, "unknown");
}

const char* type_name(int type) {
  return code_name(type, kTypeNames, "unknown");
}

// One component at p (little-endian, as glTF stores it), normalized if asked.
double load_component(const unsigned char* p, int component_type, bool normalized) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      std::int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalized ? p[0] / 255.0 : p[0];
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      std::int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      std::uint32_t v;
      std::memcpy(&v, p, 4);
      return normalized ? v / 4294967295.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default:
      return 0.0;
  }
}

// Fails unless the accessor has the type and one of the component types `kind` allows. Returns
// whether its integer components are read normalized.
bool check_kind(const Loader& loader, const tinygltf::Accessor& acc, const std::string& name,
                const AccessorKind& kind) {
  if (acc.type != kind.type)
    loader.fail(name + " has type " + type_name(acc.type) + ", expected " + type_name(kind.type));
  if (std::find(kind.component_types.begin(), kind.component_types.end(), acc.componentType) ==
      kind.component_types.end()) {
    std::string allowed;
    for (int ct : kind.component_types)
      allowed += std::string(allowed.empty() ? "" : " or ") + component_name(ct);
    loader.fail(name + " has bad component type " + std::to_string(acc.componentType) + " (" +
                component_name(acc.componentType) + "), expected " + allowed);
  }
  const bool is_int = acc.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT;
  if (kind.require_normalized_ints && is_int && !acc.normalized)
    loader.fail(name + " has integer components that are not normalized");
  return is_int && acc.normalized && kind.require_normalized_ints;
}

}  // namespace

Loader::View Loader::view(int index, const std::string& what) const {
  if (index < 0 || static_cast<std::size_t>(index) >= m_.bufferViews.size())
    fail(what + " refers to bufferView " + std::to_string(index) + ", which does not exist");
  const tinygltf::BufferView& bv = m_.bufferViews[index];
  if (bv.buffer < 0 || static_cast<std::size_t>(bv.buffer) >= m_.buffers.size())
    fail("bufferView " + std::to_string(index) + " refers to buffer " + std::to_string(bv.buffer) +
         ", which does not exist");
  const tinygltf::Buffer& buf = m_.buffers[bv.buffer];
  if (!fits(bv.byteOffset, bv.byteLength, buf.data.size()))
    fail("bufferView " + std::to_string(index) + " (byteOffset " + std::to_string(bv.byteOffset) +
         ", byteLength " + std::to_string(bv.byteLength) + ") runs past the end of buffer " +
         std::to_string(bv.buffer) + " (" + std::to_string(buf.data.size()) + " bytes)");
  return View{buf.data.data() + bv.byteOffset, bv.byteLength, bv.byteStride};
}

template <class T>
std::vector<T> Loader::read_accessor(int index, const std::string& what,
                                     const AccessorKind& kind) const {
  if (index < 0 || static_cast<std::size_t>(index) >= m_.accessors.size())
    fail(what + " refers to accessor " + std::to_string(index) + ", which does not exist");
  const tinygltf::Accessor& acc = m_.accessors[index];
  const std::string name = "accessor " + std::to_string(index) + " (" + what + ")";
  const bool normalized = check_kind(*this, acc, name, kind);
  const std::size_t comp = static_cast<std::size_t>(component_size(acc.componentType));
  const std::size_t ncomp = static_cast<std::size_t>(kind.components);
  const std::size_t elem = comp * ncomp;
  const std::size_t count = acc.count;

  std::vector<T> out;
  if (acc.bufferView >= 0) {
    View v = view(acc.bufferView, name);
    const std::size_t stride = v.stride ? v.stride : elem;
    if (stride < elem)
      fail(name + ": bufferView " + std::to_string(acc.bufferView) + " has byteStride " +
           std::to_string(stride) + ", smaller than the element size " + std::to_string(elem));
    if (count > 0) {
      // byteOffset + (count - 1) * stride + elem <= view length, without overflow.
      std::size_t span = 0;
      if (__builtin_mul_overflow(count - 1, stride, &span) ||
          !fits(acc.byteOffset, span, v.length) || !fits(acc.byteOffset + span, elem, v.length))
        fail(name + " reads past the end of bufferView " + std::to_string(acc.bufferView) + " (" +
             std::to_string(count) + " elements of " + std::to_string(elem) + " bytes, stride " +
             std::to_string(stride) + ", byteOffset " + std::to_string(acc.byteOffset) +
             ", bufferView byteLength " + std::to_string(v.length) + ")");
    }
    out.resize(count * ncomp);
    const unsigned char* base = v.data + acc.byteOffset;
    for (std::size_t i = 0; i < count; ++i)
      for (std::size_t c = 0; c < ncomp; ++c)
        out[i * ncomp + c] = static_cast<T>(
            load_component(base + i * stride + c * comp, acc.componentType, normalized));
  } else {
    if (count > kMaxUnbackedElements)
      fail(name + " has no bufferView and a count of " + std::to_string(count) +
           ", which is too large");
    out.assign(count * ncomp, T(0));
  }
  if (acc.sparse.isSparse) read_sparse(acc, name, normalized, ncomp, out);
  return out;
}

// Overrides the elements of `out` (acc.count elements of `ncomp` components) that the accessor's
// sparse part lists.
template <class T>
void Loader::read_sparse(const tinygltf::Accessor& acc, const std::string& name, bool normalized,
                         std::size_t ncomp, std::vector<T>& out) const {
  const std::size_t comp = static_cast<std::size_t>(component_size(acc.componentType));
  const std::size_t elem = comp * ncomp;
  const std::size_t count = acc.count;
  const auto& sp = acc.sparse;
  if (sp.count < 1 || static_cast<std::size_t>(sp.count) > count)
    fail(name + " has a sparse count of " + std::to_string(sp.count) + " (accessor count " +
         std::to_string(count) + ")");
  const std::size_t n = static_cast<std::size_t>(sp.count);
  const int ict = sp.indices.componentType;
  if (ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
      ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT && ict != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
    fail(name + " has sparse indices of bad component type " + std::to_string(ict) + " (" +
         component_name(ict) + "), expected UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
  const std::size_t isize = static_cast<std::size_t>(component_size(ict));
  if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0)
    fail(name + " has a negative sparse byteOffset");
  View iv = view(sp.indices.bufferView, name + " sparse indices");
  View vv = view(sp.values.bufferView, name + " sparse values");
  const std::size_t ioff = static_cast<std::size_t>(sp.indices.byteOffset);
  const std::size_t voff = static_cast<std::size_t>(sp.values.byteOffset);
  // n <= count, and count * elem fits in memory already (out was allocated), so no overflow.
  if (!fits(ioff, n * isize, iv.length))
    fail(name + " sparse indices read past the end of bufferView " +
         std::to_string(sp.indices.bufferView));
  if (!fits(voff, n * elem, vv.length))
    fail(name + " sparse values read past the end of bufferView " +
         std::to_string(sp.values.bufferView));
  for (std::size_t k = 0; k < n; ++k) {
    const double target = load_component(iv.data + ioff + k * isize, ict, false);
    if (target >= static_cast<double>(count))
      fail(name + " has sparse index " + std::to_string(static_cast<std::uint64_t>(target)) +
           " out of range (accessor count " + std::to_string(count) + ")");
    const std::size_t t = static_cast<std::size_t>(target);
    for (std::size_t c = 0; c < ncomp; ++c)
      out[t * ncomp + c] = static_cast<T>(
          load_component(vv.data + voff + k * elem + c * comp, acc.componentType, normalized));
  }
}

template std::vector<float> Loader::read_accessor<float>(int, const std::string&,
                                                         const AccessorKind&) const;
template std::vector<std::uint32_t> Loader::read_accessor<std::uint32_t>(int, const std::string&,
                                                                         const AccessorKind&) const;

}  // namespace irradcast::gltf_import
