// What an EngineHost keeps across a restart (--state-dir, docs/EDITS.md#durable-edits): the
// edit journal replayed at start, and the poses of dynamic nodes, restored at start and saved by
// their own thread as they stream (engine_host.h).
#include <chrono>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/wire/scene_package.h"

namespace irradcast {

std::uint64_t EngineHost::replay_journal() {
  loaded_state_ = prepared_.scene();
  loaded_state_.meshes.clear();  // the snapshot reads the editable state only
  loaded_state_.textures.clear();
  EditJournalOptions jo;
  jo.dir = options_.state_dir;
  jo.scene_id = scene_id_;
  scene_hash_ = wire::scene_content_hash(prepared_.scene());
  jo.scene_hash = scene_hash_;
  jo.compact_after = options_.journal_compact_after;
  journal_ = std::make_unique<EditJournal>(jo);
  const std::uint64_t revision = journal_->replay_revision();
  std::vector<SceneEdit> edits;
  std::vector<std::uint64_t> revisions;
  for (const JournalEntry& e : journal_->entries()) {
    if (e.edit.ops.empty()) continue;  // a snapshot of the scene as loaded
    edits.push_back(e.edit);
    revisions.push_back(e.revision);
  }
  journal_->release_entries();
  if (edits.empty()) return revision;
  // Checked again like any edit (the file is input); one that does not apply is skipped, as it
  // was when the engine applied it live.
  EditReport report;
  prepared_.apply(edits, &report);
  for (std::size_t i = 0; i < report.edits.size(); ++i)
    if (!report.edits[i].applied)
      log::error("journal", "edit " + std::to_string(revisions[i]) +
                                " could not be applied: " + report.edits[i].error);
  log::info("journal", scene_id_ + ": replayed " + std::to_string(report.applied) + " edits from " +
                           journal_->path().string() + ", revision " + std::to_string(revision));
  return revision;
}

void EngineHost::restore_poses() {
  pose_file_ = std::make_unique<PoseFile>(options_.state_dir, scene_id_, scene_hash_);
  const auto saved = pose_file_->read(validation_scene_, posable_);
  if (saved && !saved->second.ops.empty()) {
    try {
      apply_edit(validation_scene_, saved->second);  // checked like any edit
    } catch (const Error& e) {
      throw Error("saved poses: " + pose_file_->path().string() + ": " + e.what() +
                  "; move it away to start without the saved poses");
    }
    std::map<int, NodePoseState> poses;
    for (const EditOp& op : saved->second.ops) {
      const int n = std::stoi(op.target.substr(1));  // "#n", as pose_edit made it
      poses[n] =
          NodePoseState{validation_scene_.nodes[n].local, validation_scene_.nodes[n].visible};
    }
    log::info("journal", scene_id_ + ": restored the poses of " + std::to_string(poses.size()) +
                             " nodes from " + pose_file_->path().string());
    poses_.restore(std::move(poses), saved->first);
  } else if (saved) {
    poses_.restore({}, saved->first);
  }
}

void EngineHost::save_poses() {
  std::unique_lock lock(saver_mutex_);
  for (;;) {
    saver_cv_.wait(lock, [&] { return poses_dirty_ || saver_stop_; });
    if (!poses_dirty_) return;  // stopping, and everything saved
    poses_dirty_ = false;
    lock.unlock();
    SavedPoses s;
    s.poses = poses_.snapshot(&s.sequence);
    bool saved = true;
    try {
      pose_file_->write(s);
    } catch (const Error& e) {
      log::error("journal",
                 std::string("streamed poses not saved (tried again in 1 s): ") + e.what());
      saved = false;
    }
    lock.lock();
    if (!saved) {
      poses_dirty_ = true;
      if (saver_stop_) return;  // no second try at a stop
      saver_cv_.wait_for(lock, std::chrono::seconds(1), [&] { return saver_stop_; });
      continue;
    }
    saver_cv_.wait_for(lock, kPoseSaveInterval, [&] { return saver_stop_; });
  }
}

}  // namespace irradcast
