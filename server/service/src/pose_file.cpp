#include "irradcast/service/pose_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "irradcast/common/error.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast_state.pb.h"

namespace irradcast {
namespace {

constexpr std::uint32_t kFormat = 1;

std::string errno_text() {
  return std::strerror(errno);
}

void fsync_path(const std::filesystem::path& p, int flags, const std::string& what) {
  const int fd = ::open(p.c_str(), flags | O_CLOEXEC);
  if (fd < 0) throw Error(what + ": cannot open " + p.string() + ": " + errno_text());
  const int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0) throw Error(what + ": fsync of " + p.string() + " failed: " + errno_text());
}

}  // namespace

PoseFile::PoseFile(std::filesystem::path dir, std::string scene_id, std::string scene_hash)
    : dir_(std::move(dir)),
      path_(dir_ / kFileName),
      scene_id_(std::move(scene_id)),
      scene_hash_(std::move(scene_hash)) {}

std::optional<std::pair<std::uint64_t, SceneEdit>> PoseFile::read(
    const Scene& scene, const std::vector<bool>& posable) const {
  std::error_code ec;
  if (!std::filesystem::exists(path_, ec)) return std::nullopt;
  const std::string where = "saved poses: " + path_.string();
  const std::uintmax_t size = std::filesystem::file_size(path_, ec);
  if (ec) throw Error(where + ": " + ec.message());
  if (size > kMaxBytes)
    throw Error(where + " is " + std::to_string(size) + " bytes (at most " +
                std::to_string(kMaxBytes) + "); move it away to start without the saved poses");
  std::ifstream f(path_, std::ios::binary);
  std::ostringstream bytes;
  bytes << f.rdbuf();
  wire::PoseSnapshot snapshot;
  if (!f || !snapshot.ParseFromString(bytes.str()) || snapshot.format() != kFormat)
    throw Error(where + " is damaged (not a pose snapshot of format " + std::to_string(kFormat) +
                "); move it away to start without the saved poses");
  if (snapshot.scene_hash() != scene_hash_)
    throw Error(where + " belongs to another scene (content hash " +
                wire::hex(snapshot.scene_hash()) + ", this scene '" + scene_id_ + "' hashes to " +
                wire::hex(scene_hash_) + "); give another --state-dir");
  if (snapshot.sequence() > (std::uint64_t{1} << 62))
    throw Error(where + " holds pose sequence " + std::to_string(snapshot.sequence()) +
                ", more than a server reaches; move it away to start without the saved poses");
  wire::Poses poses;
  *poses.mutable_poses() = snapshot.poses();
  try {
    if (poses.poses_size() == 0) return std::make_pair(snapshot.sequence(), SceneEdit{});
    return std::make_pair(snapshot.sequence(), wire::pose_edit(poses, scene, posable));
  } catch (const Error& e) {
    throw Error(where + ": " + e.what());
  }
}

void PoseFile::write(const SavedPoses& saved) {
  std::lock_guard lock(mutex_);
  if (written_ && *written_ >= saved.sequence) return;
  wire::PoseSnapshot snapshot;
  snapshot.set_format(kFormat);
  snapshot.set_scene_hash(scene_hash_);
  snapshot.set_sequence(saved.sequence);
  for (const auto& [node, pose] : saved.poses)
    *snapshot.add_poses() =
        wire::node_pose_to_proto(static_cast<std::uint32_t>(node), pose.local, pose.visible);
  const std::string bytes = snapshot.SerializeAsString();
  const std::filesystem::path tmp = dir_ / (std::string(kFileName) + ".tmp");
  const std::string what = "saved poses";
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
  if (fd < 0) throw Error(what + ": cannot create " + tmp.string() + ": " + errno_text());
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = errno_text();
      ::close(fd);
      throw Error(what + ": write of " + tmp.string() + " failed: " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  const int rc = ::fdatasync(fd);
  ::close(fd);
  if (rc != 0) throw Error(what + ": fsync of " + tmp.string() + " failed: " + errno_text());
  if (::rename(tmp.c_str(), path_.c_str()) != 0)
    throw Error(what + ": cannot rename " + tmp.string() + ": " + errno_text());
  fsync_path(dir_, O_RDONLY | O_DIRECTORY, what);
  written_ = saved.sequence;
}

}  // namespace irradcast
