// The saved poses (irradcast-server --state-dir DIR, docs/DYNAMIC.md#poses): DIR/poses holds the
// newest pose of every posed node as one PoseSnapshot (proto/irradcast_state.proto), rewritten
// whole: written to a temporary file, fsynced, renamed over the old one, and the folder fsynced.
// A crash leaves the old file or the new one, never a mix.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "irradcast/common/scene_edit.h"
#include "irradcast/service/pose_board.h"

namespace irradcast {

struct SavedPoses {
  std::uint64_t sequence = 0;
  std::map<int, NodePoseState> poses;
};

class PoseFile {
 public:
  static constexpr const char* kFileName = "poses";
  static constexpr std::uintmax_t kMaxBytes = 64u << 20;

  // `scene_hash`: wire::scene_content_hash of the scene as loaded, as the journal's.
  PoseFile(std::filesystem::path dir, std::string scene_id, std::string scene_hash);

  // The poses saved before (nullopt: no file), as the absolute edit that gives each node its pose
  // (wire::pose_edit: targets by index; the host checks it like any edit). Throws
  // irradcast::Error with a clear message on a file that is damaged or another scene's.
  // `posable`: pose_nodes(scene).
  std::optional<std::pair<std::uint64_t, SceneEdit>> read(const Scene& scene,
                                                          const std::vector<bool>& posable) const;
  // Replaces the file with `poses`, unless it holds their sequence or a later one already (a
  // slower writer's older snapshot never replaces a newer one). Throws irradcast::Error on an I/O
  // failure. Any thread.
  void write(const SavedPoses& poses);
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path dir_, path_;
  std::string scene_id_, scene_hash_;
  std::mutex mutex_;
  std::optional<std::uint64_t> written_;  // the sequence on disk (mutex_)
};

}  // namespace irradcast
