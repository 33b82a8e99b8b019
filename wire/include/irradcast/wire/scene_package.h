// The scene download payload: everything a client needs to render its own view (nodes, meshes,
// materials, textures, lights, cameras: the irradcast::Scene model, stored exactly; the sky, with
// a map at most 1024 x 512 in RGB9E5 for the background only: sky_message.h) plus the
// lightmap layout of every object (irradcast::Atlas), as a zstd-compressed SceneData message
// (proto/irradcast.proto). Identified by the SHA-256 of the compressed bytes, so a client can
// cache it and skip the download when Welcome.scene_hash matches.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "irradcast.pb.h"
#include "irradcast/common/atlas.h"
#include "irradcast/common/scene.h"

namespace irradcast::wire {

constexpr std::uint32_t kSceneFormat = 1;
// Largest uncompressed SceneData accepted (and produced).
constexpr std::size_t kMaxSceneDataBytes = std::size_t{1} << 30;
// SceneChunk.data size a server should use: far below the frame cap, small enough to interleave.
constexpr std::size_t kDefaultSceneChunkBytes = std::size_t{1} << 20;

struct ScenePackage {
  std::string bytes;  // zstd(serialized SceneData)
  std::string hash;   // SHA-256 of `bytes`: 32 raw bytes (hex() for file names and logs)
};

// Throws irradcast::Error if the atlas does not match the scene's objects or the scene holds
// invalid data (indices out of range, non-finite positions). `revision` counts the scene edits
// applied since the scene was loaded (docs/EDITS.md).
ScenePackage make_scene_package(const Scene& scene, const Atlas& atlas, std::uint64_t revision = 0);

// Identifies a scene as loaded, apart from its lightmap layout and revision: the SHA-256 (32 raw
// bytes) of its SceneData without layouts, serialized deterministically. The edit journal keys
// its edits by it (a server started with other texel options keeps its edits). Throws like
// make_scene_package on invalid scene data.
std::string scene_content_hash(const Scene& scene);

struct UnpackedScene {
  Scene scene;
  Atlas atlas;
  std::uint64_t revision = 0;  // edits the package's scene includes
};
// Parses and validates. Throws irradcast::Error with a clear message on a hash mismatch, corrupt
// data, indices out of range, or a layout that does not match the scene's objects. An empty
// expected_hash skips the hash check.
UnpackedScene open_scene_package(const std::string& bytes, const std::string& expected_hash);

// Splits bytes into pieces of chunk_size (the last one shorter). Throws if chunk_size is 0.
std::vector<std::string> chunk(const std::string& bytes, std::size_t chunk_size);

// Collects SceneChunks on the client. add() checks each chunk against the Welcome's hash and
// size and against the bytes so far (chunks must arrive in order, without gaps) and returns true
// when the package is complete; it throws irradcast::Error on an inconsistent chunk.
class SceneAssembler {
 public:
  SceneAssembler(std::string expected_hash, std::uint64_t total);
  bool add(const SceneChunk& c);
  bool complete() const { return bytes_.size() == total_; }
  std::uint64_t received() const { return bytes_.size(); }
  const std::string& bytes() const { return bytes_; }

 private:
  std::string hash_;
  std::uint64_t total_;
  std::string bytes_;
};

// SHA-256 of data, 32 raw bytes.
std::string sha256(const std::string& data);
// Lower-case hex of raw bytes.
std::string hex(const std::string& raw);

}  // namespace irradcast::wire
