// The durable edit journal (irradcast-server --state-dir DIR, docs/EDITS.md#durable-edits): every
// accepted scene edit is appended to DIR/edits.journal and fsynced before the server acknowledges
// it, so what a user changed survives kill -9 and power loss. A restart on the same scene replays
// the journal; past `compact_after` records the journal is rewritten as one snapshot (the edit
// from the scene as loaded to the state of the last revision) in a new file that atomically
// replaces the old one.
//
// The file: 8 bytes of magic, then records, each a 4-byte little-endian length, the first 8 bytes
// of the SHA-256 of the payload, and the payload (a JournalRecord, proto/irradcast_state.proto).
// The first record is the header (the scene's content hash). A record whose length runs past the
// end of the file or whose checksum does not match (a write torn by a crash or power loss, or a
// damaged disk) ends the journal there: the rest is cut off with one warning. Everything in the
// file is checked as hostile input: lengths are bounded, edits are checked again by the host.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "irradcast/common/scene_edit.h"

namespace irradcast {

namespace wire {
class JournalRecord;
}

struct EditJournalOptions {
  std::filesystem::path dir;  // created if missing (one level)
  std::string scene_id;       // for messages
  std::string scene_hash;     // wire::scene_content_hash of the scene as loaded (32 raw bytes)
  // Rewrite the journal as one snapshot once it holds this many edit records (0: never).
  std::uint32_t compact_after = 1000;
};

struct JournalEntry {
  std::uint64_t revision = 0;
  bool snapshot = false;  // the edit takes the scene as loaded to this revision's state
  SceneEdit edit;
};

class EditJournal {
 public:
  // Largest record accepted (a sky map of 4096 x 2048 floats is 96 MiB before zstd).
  static constexpr std::uint32_t kMaxRecordBytes = 128u << 20;
  static constexpr const char* kFileName = "edits.journal";
  // A journal this large is compacted whatever its count (sky maps make records large, and
  // replay decodes them all before it applies them).
  static constexpr std::uint64_t kCompactBytes = 256u << 20;

  // Opens DIR/edits.journal (creating DIR and the file with its header if missing), locks it
  // against a second server, and reads it: entries() are then the edits to replay, in order.
  // Throws irradcast::Error with a clear message when DIR is not usable, another process holds
  // the lock, the file is not a journal, or it belongs to another scene (naming both hashes). A
  // torn or corrupt tail is cut off (truncated on disk) with one warning, never an error.
  explicit EditJournal(EditJournalOptions options);
  ~EditJournal();
  EditJournal(const EditJournal&) = delete;
  EditJournal& operator=(const EditJournal&) = delete;

  // What was read at open: the snapshot (if any) first, then the edits after it.
  const std::vector<JournalEntry>& entries() const { return entries_; }
  // The revision of the last entry read at open (0: none).
  std::uint64_t replay_revision() const { return entries_.empty() ? 0 : entries_.back().revision; }
  // Bytes cut off at open (0: the file ended cleanly).
  std::uint64_t cut_bytes() const { return cut_bytes_; }
  // Drops the entries read at open (the host has replayed them).
  void release_entries() {
    entries_.clear();
    entries_.shrink_to_fit();
  }

  // Appends `edit` as `revision` and fsyncs the file: when this returns, the edit is on disk.
  // Revisions must increase by one from the last record. Throws irradcast::Error on an I/O
  // failure; the journal then refuses every later append (the file's state is unknown after a
  // failed fsync), so no edit is acknowledged that would not survive.
  void append(std::uint64_t revision, const SceneEdit& edit);
  // Throws the error append() would throw after an earlier failure (a host checks before it
  // takes an edit's poses, which are saved apart: docs/DYNAMIC.md#moving-them-poses).
  void check_usable() const;
  // Whether the journal holds compact_after edit records since its last snapshot, or
  // kCompactBytes.
  bool wants_compaction() const;
  // Writes a new journal holding the header and `snapshot` (the state of `revision`, the last
  // appended one) to a temporary file, fsyncs it, renames it over the journal and fsyncs the
  // folder: a crash at any point leaves either the old journal or the new one. Throws
  // irradcast::Error on failure: the old journal stays in use, unless only the folder's fsync
  // after the rename failed, which fails the journal like a failed append.
  void compact(std::uint64_t revision, const SceneEdit& snapshot);

  std::uint64_t records() const { return records_; }        // edit records since the snapshot
  std::uint64_t file_bytes() const { return file_bytes_; }  // the journal's size
  const std::filesystem::path& path() const { return path_; }

 private:
  void read_existing();
  void take_record(const wire::JournalRecord& r, const std::string& where, bool& header);
  void create_new();
  // Writes magic, header and `records` to a temporary file, renames it over the journal and
  // appends to it from then on.
  void write_fresh(const std::string& records);

  EditJournalOptions options_;
  std::filesystem::path path_;
  int fd_ = -1;
  int lock_fd_ = -1;  // DIR/lock, flock()ed while the journal is open
  bool failed_ = false;
  std::string failure_;
  std::vector<JournalEntry> entries_;
  std::uint64_t last_revision_ = 0;
  std::uint64_t records_ = 0;
  std::uint64_t file_bytes_ = 0;
  std::uint64_t cut_bytes_ = 0;
};

}  // namespace irradcast
