#include "irradcast/service/edit_journal.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <memory>

#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/sky.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/scene_package.h"
#include "irradcast_state.pb.h"

namespace irradcast {
namespace {

constexpr char kMagic[8] = {'I', 'R', 'C', 'J', 'R', 'N', '0', '1'};
constexpr std::size_t kRecordHead = 4 + 8;  // length, checksum
constexpr std::uint32_t kFormat = 1;

std::string errno_text() {
  return std::strerror(errno);
}

std::string checksum(const std::string& payload) {
  return wire::sha256(payload).substr(0, 8);
}

// The framed record: length (little-endian), checksum, payload.
std::string frame(const wire::JournalRecord& record) {
  std::string payload;
  if (!record.SerializeToString(&payload)) throw Error("edit journal: cannot serialize a record");
  if (payload.size() > EditJournal::kMaxRecordBytes)
    throw Error("edit journal: the record is " + std::to_string(payload.size()) +
                " bytes, more than the journal takes (" +
                std::to_string(EditJournal::kMaxRecordBytes) + ")");
  std::string out(4, '\0');
  const auto n = static_cast<std::uint32_t>(payload.size());
  for (int i = 0; i < 4; ++i) out[static_cast<std::size_t>(i)] = static_cast<char>(n >> (8 * i));
  out += checksum(payload);
  out += payload;
  return out;
}

// Writes all of `data` at the end of fd (O_APPEND), then fdatasync.
void write_durably(int fd, const std::string& data, const std::string& what) {
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(what + ": write failed: " + errno_text());
    done += static_cast<std::size_t>(n);
  }
  if (::fdatasync(fd) != 0) throw Error(what + ": fsync failed: " + errno_text());
}

void sync_dir(const std::filesystem::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) throw Error("edit journal: cannot open " + dir.string() + ": " + errno_text());
  const int rc = ::fsync(fd);
  ::close(fd);
  if (rc != 0) throw Error("edit journal: fsync of " + dir.string() + " failed: " + errno_text());
}

wire::JournalSkyMap encode_map(std::uint32_t op, const ImageRGB& map) {
  wire::JournalSkyMap m;
  m.set_op(op);
  m.set_width(static_cast<std::uint32_t>(map.width));
  m.set_height(static_cast<std::uint32_t>(map.height));
  const std::size_t raw = map.pixels.size() * sizeof(glm::vec3);
  std::string out(ZSTD_compressBound(raw), '\0');
  const std::size_t n = ZSTD_compress(out.data(), out.size(), map.pixels.data(), raw, 3);
  if (ZSTD_isError(n))
    throw Error(std::string("edit journal: cannot compress a sky map: ") + ZSTD_getErrorName(n));
  out.resize(n);
  m.set_rgb32f_zstd(std::move(out));
  return m;
}

ImageRGB decode_map(const wire::JournalSkyMap& m, const std::string& where) {
  if (m.width() == 0 || m.height() == 0 || m.width() > static_cast<std::uint32_t>(kMaxSkyWidth) ||
      m.height() > static_cast<std::uint32_t>(kMaxSkyHeight))
    throw Error(where + ": a sky map of " + std::to_string(m.width()) + " x " +
                std::to_string(m.height()) + " texels");
  ImageRGB map(static_cast<int>(m.width()), static_cast<int>(m.height()));
  const std::size_t raw = map.pixels.size() * sizeof(glm::vec3);
  const std::string& z = m.rgb32f_zstd();
  const unsigned long long declared = ZSTD_getFrameContentSize(z.data(), z.size());
  if (declared != raw) throw Error(where + ": a sky map whose data is not its size");
  const std::size_t n = ZSTD_decompress(map.pixels.data(), raw, z.data(), z.size());
  if (ZSTD_isError(n) || n != raw) throw Error(where + ": a sky map whose data does not decode");
  Sky sky;
  sky.map = std::move(map);
  validate_sky(sky, where + ": its sky map");
  return std::move(sky.map);
}

wire::JournalRecord edit_record(std::uint64_t revision, bool snapshot, const SceneEdit& edit) {
  wire::JournalRecord r;
  wire::JournalEdit* e = r.mutable_edit();
  e->set_revision(revision);
  e->set_snapshot(snapshot);
  e->set_accepted_us(
      static_cast<std::uint64_t>(std::chrono::duration_cast<std::chrono::microseconds>(
                                     std::chrono::system_clock::now().time_since_epoch())
                                     .count()));
  wire::to_proto(edit, e->mutable_edit());
  // Sky maps exactly, instead of the viewers' copy that to_proto writes.
  for (std::size_t i = 0; i < edit.ops.size(); ++i) {
    const EditOp& op = edit.ops[i];
    if (op.kind != EditOp::Kind::Sky || !op.sky_map) continue;
    e->mutable_edit()->mutable_ops(static_cast<int>(i))->clear_sky_map();
    *e->add_sky_maps() = encode_map(static_cast<std::uint32_t>(i), *op.sky_map);
  }
  return r;
}

JournalEntry entry_of(const wire::JournalEdit& e, const std::string& where) {
  JournalEntry entry;
  entry.revision = e.revision();
  entry.snapshot = e.snapshot();
  entry.edit = wire::from_proto(e.edit());
  for (const wire::JournalSkyMap& m : e.sky_maps()) {
    if (m.op() >= entry.edit.ops.size() || entry.edit.ops[m.op()].kind != EditOp::Kind::Sky)
      throw Error(where + ": a sky map for op " + std::to_string(m.op()) + ", not a sky op");
    entry.edit.ops[m.op()].sky_map = std::make_shared<const ImageRGB>(decode_map(m, where));
  }
  for (std::size_t i = 0; i < entry.edit.ops.size(); ++i) {
    const EditOp& op = entry.edit.ops[i];
    if (op.kind == EditOp::Kind::Sky && (op.sky_parts & EditOp::kSkyFile) && !op.sky_map)
      throw Error(where + ": sky op " + std::to_string(i + 1) + " names a file but has no map");
  }
  return entry;
}

// Reads exactly n bytes at offset; false at the end of the file.
bool read_at(int fd, std::uint64_t offset, char* out, std::size_t n) {
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = ::pread(fd, out + done, n - done, static_cast<off_t>(offset + done));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) throw Error("edit journal: read failed: " + errno_text());
    if (r == 0) return false;
    done += static_cast<std::size_t>(r);
  }
  return true;
}

}  // namespace

EditJournal::EditJournal(EditJournalOptions options)
    : options_(std::move(options)), path_(options_.dir / kFileName) {
  if (options_.scene_hash.size() != 32) throw Error("edit journal: the scene hash is not SHA-256");
  std::error_code ec;
  const bool created = std::filesystem::create_directory(options_.dir, ec);
  if (ec || !std::filesystem::is_directory(options_.dir))
    throw Error("--state-dir " + options_.dir.string() + ": not a folder the server can use" +
                (ec ? " (" + ec.message() + ")" : std::string()));
  // A new folder survives a power cut only once its parent's entry is on disk.
  if (created) sync_dir(std::filesystem::absolute(options_.dir).parent_path());
  lock_fd_ = ::open((options_.dir / "lock").c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (lock_fd_ < 0)
    throw Error("--state-dir " + options_.dir.string() +
                ": cannot create its lock file: " + errno_text());
  if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
    ::close(lock_fd_);
    throw Error("--state-dir " + options_.dir.string() +
                ": another irradcast-server is using it (its lock is held)");
  }
  try {
    if (std::filesystem::exists(path_))
      read_existing();
    else
      create_new();
  } catch (...) {
    if (fd_ >= 0) ::close(fd_);
    ::close(lock_fd_);
    throw;
  }
}

EditJournal::~EditJournal() {
  if (fd_ >= 0) ::close(fd_);
  if (lock_fd_ >= 0) ::close(lock_fd_);
}

void EditJournal::create_new() {
  // A new journal is written whole to a temporary file and renamed into place: a crash leaves
  // no journal or a complete header, never half a header.
  write_fresh({});
}

void EditJournal::write_fresh(const std::string& records) {
  const std::filesystem::path tmp = options_.dir / (std::string(kFileName) + ".tmp");
  // Opened for appending: once renamed, this descriptor is the journal, so nothing can fail
  // between the rename and the next append but the folder's fsync.
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_APPEND | O_CLOEXEC, 0600);
  if (fd < 0) throw Error("edit journal: cannot create " + tmp.string() + ": " + errno_text());
  wire::JournalRecord header;
  header.mutable_header()->set_format(kFormat);
  header.mutable_header()->set_scene_hash(options_.scene_hash);
  header.mutable_header()->set_scene_id(options_.scene_id);
  const std::string bytes = std::string(kMagic, sizeof kMagic) + frame(header) + records;
  try {
    write_durably(fd, bytes, "edit journal " + tmp.string());
    if (::rename(tmp.c_str(), path_.c_str()) != 0)
      throw Error("edit journal: cannot rename " + tmp.string() + ": " + errno_text());
  } catch (...) {
    ::close(fd);
    throw;  // the journal in use is unchanged
  }
  if (fd_ >= 0) ::close(fd_);
  fd_ = fd;
  file_bytes_ = bytes.size();
  try {
    sync_dir(options_.dir);
  } catch (const Error& e) {
    // The rename may not survive a power cut (the old journal would come back without what is
    // appended from now on): no edit is acknowledged any more.
    failed_ = true;
    failure_ = e.what();
    throw;
  }
}

// One record read back: the header first (its format and scene checked), then edits in
// revision order.
void EditJournal::take_record(const wire::JournalRecord& r, const std::string& where,
                              bool& header) {
  if (!header) {
    if (!r.has_header() || r.header().format() != kFormat)
      throw Error(where + " is not a journal header of format " + std::to_string(kFormat));
    if (r.header().scene_hash() != options_.scene_hash)
      throw Error("--state-dir " + options_.dir.string() + " holds the edits of scene '" +
                  r.header().scene_id() + "' (content hash " + wire::hex(r.header().scene_hash()) +
                  "), but this scene '" + options_.scene_id + "' hashes to " +
                  wire::hex(options_.scene_hash) +
                  ": start with that scene, or give another --state-dir");
    header = true;
  } else {
    if (!r.has_edit()) throw Error(where + " is a second header");
    JournalEntry e = entry_of(r.edit(), where);
    const bool first = entries_.empty();
    if (e.snapshot ? !first : e.revision != last_revision_ + 1)
      throw Error(where + " has revision " + std::to_string(e.revision) + " after revision " +
                  std::to_string(last_revision_) + (e.snapshot ? " (a snapshot not first)" : ""));
    last_revision_ = e.revision;
    if (!e.snapshot) ++records_;
    entries_.push_back(std::move(e));
  }
}

void EditJournal::read_existing() {
  const int fd = ::open(path_.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) throw Error("edit journal: cannot open " + path_.string() + ": " + errno_text());
  fd_ = fd;
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode))
    throw Error("edit journal: " + path_.string() + " is not a regular file");
  const auto size = static_cast<std::uint64_t>(st.st_size);
  char magic[sizeof kMagic];
  if (!read_at(fd, 0, magic, sizeof magic) || std::memcmp(magic, kMagic, sizeof kMagic) != 0)
    throw Error("edit journal: " + path_.string() +
                " is not an irradcast edit journal (move it away to start without it)");
  std::uint64_t at = sizeof kMagic;
  bool header = false;
  std::string cut_why;
  while (at < size) {
    char head[kRecordHead];
    if (!read_at(fd, at, head, kRecordHead)) {
      cut_why = "a record's length is cut off";
      break;
    }
    std::uint32_t n = 0;
    for (int i = 0; i < 4; ++i)
      n |= static_cast<std::uint32_t>(static_cast<unsigned char>(head[i])) << (8 * i);
    if (n == 0 || n > kMaxRecordBytes || n > size - at - kRecordHead) {
      cut_why = "a record of " + std::to_string(n) + " bytes runs past the end of the file";
      break;
    }
    std::string payload(n, '\0');
    if (!read_at(fd, at + kRecordHead, payload.data(), n)) {
      cut_why = "a record is cut off";
      break;
    }
    if (checksum(payload) != std::string(head + 4, 8)) {
      cut_why = "a record's checksum does not match";
      break;
    }
    wire::JournalRecord r;
    const std::string where =
        "edit journal " + path_.string() + ": the record at byte " + std::to_string(at);
    if (!r.ParseFromString(payload))
      throw Error(where + " does not parse (its checksum matches: not a torn write)");
    take_record(r, where, header);
    at += kRecordHead + n;
  }
  if (!header) throw Error("edit journal: " + path_.string() + " has no header");
  if (at < size) {
    cut_bytes_ = size - at;
    log::warn(
        "journal",
        path_.string() + ": " + cut_why + " after revision " + std::to_string(last_revision_) +
            "; cutting off the last " + std::to_string(cut_bytes_) +
            " bytes (a write torn by a crash, which was never acknowledged, or damaged data)");
    if (::ftruncate(fd, static_cast<off_t>(at)) != 0 || ::fsync(fd) != 0)
      throw Error("edit journal: cannot cut off the torn tail of " + path_.string() + ": " +
                  errno_text());
  }
  file_bytes_ = at;
  // Appends go to the end from now on.
  ::close(fd_);
  fd_ = ::open(path_.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd_ < 0) throw Error("edit journal: cannot open " + path_.string() + ": " + errno_text());
}

void EditJournal::check_usable() const {
  if (failed_)
    throw Error("the edit journal failed earlier (" + failure_ +
                "); edits are refused until the server is restarted");
}

void EditJournal::append(std::uint64_t revision, const SceneEdit& edit) {
  check_usable();
  if (revision != last_revision_ + 1)
    throw Error("edit journal: revision " + std::to_string(revision) + " after " +
                std::to_string(last_revision_));
  const std::string bytes = frame(edit_record(revision, false, edit));
  try {
    write_durably(fd_, bytes, "edit journal " + path_.string());
  } catch (const Error& e) {
    // Best effort: the record may have reached the disk although its fsync failed, and the
    // client is told the edit was refused, so it must not come back at the next start.
    if (::ftruncate(fd_, static_cast<off_t>(file_bytes_)) == 0) ::fdatasync(fd_);
    failed_ = true;
    failure_ = e.what();
    log::error("journal", failure_ + ": refusing every edit from now on");
    throw Error("the edit could not be made durable: " + failure_);
  }
  last_revision_ = revision;
  ++records_;
  file_bytes_ += bytes.size();
}

bool EditJournal::wants_compaction() const {
  // By count, and by size: replay holds every record's sky maps in memory at once.
  return records_ > 0 && ((options_.compact_after > 0 && records_ >= options_.compact_after) ||
                          file_bytes_ >= kCompactBytes);
}

void EditJournal::compact(std::uint64_t revision, const SceneEdit& snapshot) {
  if (failed_) return;
  if (revision != last_revision_)
    throw Error("edit journal: a snapshot of revision " + std::to_string(revision) +
                " while the journal is at " + std::to_string(last_revision_));
  const std::uint64_t before = file_bytes_;
  write_fresh(frame(edit_record(revision, true, snapshot)));
  records_ = 0;
  log::info("journal", "compacted " + path_.string() + " at revision " + std::to_string(revision) +
                           ": " + std::to_string(before) + " -> " + std::to_string(file_bytes_) +
                           " bytes");
}

}  // namespace irradcast
