// irradcast-edit --stream (docs/DYNAMIC.md#poses): poses of dynamic nodes sent as the lines
// of a file or stdin come.
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <fstream>
#include <iostream>
#include <map>
#include <mutex>
#include <thread>

#include "edit_session.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/edit_message.h"

namespace irradcast::edit_tool {

namespace {

// The lines of a file or stdin, read on their own thread so that the connection is served (pings,
// refusals) while no line comes. The thread is detached (stdin may block for good after the last
// line the tool needs) and shares the lines with the reader: it may outlive it.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : shared_(std::make_shared<Shared>()) {
    auto in = std::make_shared<std::ifstream>();
    if (!path.empty()) {
      in->open(path);
      if (!*in) throw irradcast::Error("--stream: cannot read '" + path + "'");
    }
    std::thread([shared = shared_, in, use_stdin = path.empty()] {
      std::istream& from = use_stdin ? std::cin : *in;
      std::string line;
      while (std::getline(from, line)) {
        std::unique_lock lock(shared->mutex);
        // A bounded backlog: a file is read no faster than the poses go out.
        shared->cv.wait(lock, [&] { return shared->lines.size() < 1024 || shared->abandoned; });
        if (shared->abandoned) return;
        shared->lines.push_back(std::move(line));
        shared->cv.notify_all();
      }
      std::lock_guard lock(shared->mutex);
      shared->done = true;
      shared->cv.notify_all();
    }).detach();
  }
  ~LineReader() {
    std::lock_guard lock(shared_->mutex);
    shared_->abandoned = true;
    shared_->cv.notify_all();
  }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  // The next line within `wait`; nullopt when none came (`ended`: none will).
  std::optional<std::string> next(std::chrono::milliseconds wait, bool& ended) {
    Shared& s = *shared_;
    std::unique_lock lock(s.mutex);
    s.cv.wait_for(lock, wait, [&] { return !s.lines.empty() || s.done; });
    ended = s.lines.empty() && s.done;
    if (s.lines.empty()) return std::nullopt;
    std::string line = std::move(s.lines.front());
    s.lines.pop_front();
    s.cv.notify_all();
    return line;
  }

 private:
  struct Shared {
    std::mutex mutex;
    std::condition_variable cv;
    std::deque<std::string> lines;
    bool done = false, abandoned = false;
  };
  std::shared_ptr<Shared> shared_;
};

// One --stream run: the lines read, the poses sent, what the server refused, and what a lost
// connection may have taken with it.
class PoseStream {
 public:
  PoseStream(const Options& o, const std::string& token)
      : o_(o), token_(token), session_(o, tools::start_run(o.log_level, o.connect)) {}

  // Sends each line as it comes, serving the connection while none does.
  void send_lines(LineReader& reader) {
    for (;;) {
      bool ended = false;
      std::optional<std::string> line = reader.next(std::chrono::milliseconds(50), ended);
      if (ended) return;
      if (!line) {
        serve(Clock::now());
        continue;
      }
      ++line_no_;
      const std::size_t first = line->find_first_not_of(" \t\r");
      if (first == std::string::npos || (*line)[first] == '#') continue;
      SceneEdit edit;
      try {
        edit = parse_edit_json(*line);
      } catch (const Error& e) {
        ++refused_;
        std::fprintf(stderr, "irradcast-edit: line %llu: %s\n",
                     static_cast<unsigned long long>(line_no_), e.what());
        continue;
      }
      send(edit);
    }
  }

  // Every refusal is in before the answer to a ping sent after the last pose; prints the
  // summary. 0 when every line was taken.
  int finish() {
    wire::Envelope ping;
    ping.mutable_ping()->set_nonce(kLastPing);
    session_.connection().send(ping);
    const auto deadline = Clock::now() + std::chrono::milliseconds(o_.timeout_ms);
    for (bool ponged = false; !ponged;) {
      std::optional<wire::Envelope> a;
      try {
        a = session_.connection().read(deadline);
      } catch (const Refused& r) {
        refusal(r);
        continue;
      }
      if (!a)
        throw Error("no answer from the server within " + std::to_string(o_.timeout_ms) + " ms");
      ponged = a->has_pong() && a->pong().nonce() == kLastPing;
    }
    session_.connection().close();
    std::printf("streamed %llu poses from %llu lines in %.2f s, %llu refused, %llu lost\n",
                static_cast<unsigned long long>(sent_ - refused_by_server_ - lost_lines_),
                static_cast<unsigned long long>(line_no_),
                std::chrono::duration<double>(Clock::now() - began_).count(),
                static_cast<unsigned long long>(refused_),
                static_cast<unsigned long long>(lost_lines_));
    return refused_ == 0 && lost_lines_ == 0 ? 0 : 1;
  }

 private:
  static constexpr auto kGap = std::chrono::microseconds(1000000 / 60);  // PoseBoard::kStreamRate
  static constexpr std::uint64_t kMark = std::uint64_t{1} << 62;         // our pings: kMark | sent
  static constexpr std::uint64_t kLastPing = 0x5157;

  // Sends one edit as soon as its nodes' rate allows, serving the connection meanwhile.
  void send(const SceneEdit& edit) {
    Clock::time_point at = Clock::now();
    for (const EditOp& op : edit.ops)
      if (auto it = last_sent_.find(op.target); it != last_sent_.end())
        at = std::max(at, it->second + kGap);
    serve(at);
    wire::Envelope e;
    wire::to_proto(edit, e.mutable_scene_edit());
    e.mutable_scene_edit()->set_token(token_);
    e.mutable_scene_edit()->set_request_id(line_no_);
    e.mutable_scene_edit()->set_stream(true);
    try {
      session_.connection().send(e);
    } catch (const Lost& lost) {
      ++lost_unsent_;
      next_server(lost, "line " + std::to_string(line_no_) + " and those sent after line " +
                            std::to_string(answered_));
      return;
    }
    ++sent_;
    ++sent_since_answer_;
    const auto now = Clock::now();
    for (const EditOp& op : edit.ops) last_sent_[op.target] = now;
  }

  // Reads what the server sent until `until`: refusals are printed, the rest dropped.
  void serve(Clock::time_point until) {
    for (;;) {
      try {
        Connection& c = session_.connection();
        mark(c);
        // A look at the socket at least every 20 ms, so that refusals do not pile up unread,
        // but not a wait for every line of a fast stream.
        const auto now = Clock::now();
        if (until <= now && now - last_poll_ < std::chrono::milliseconds(20)) return;
        last_poll_ = now;
        const std::optional<wire::Envelope> a =
            c.read(std::max(until, now + std::chrono::milliseconds(1)));
        if (!a) return;
        if (a->has_pong() && (a->pong().nonce() & kMark)) answered(a->pong().nonce() & ~kMark);
      } catch (const Refused& r) {
        refusal(r);
      } catch (const Lost& lost) {
        next_server(lost, "poses sent after line " + std::to_string(answered_));
        return;
      }
    }
  }

  // A ping every 250 ms while lines go out (and as the idle timeout needs): its pong says the
  // server read every line sent before it.
  void mark(Connection& c) {
    if (Clock::now() - last_mark_ < std::chrono::milliseconds(250) &&
        Clock::now() - c.last_send() < c.ping_every)
      return;
    wire::Envelope p;
    p.mutable_ping()->set_nonce(kMark | sent_);
    c.send(p);
    marks_[sent_] = line_no_;
    last_mark_ = Clock::now();
  }

  // The pong of the ping sent after `at` poses.
  void answered(std::uint64_t at) {
    if (auto it = marks_.find(at); it != marks_.end()) {
      answered_ = it->second;
      sent_since_answer_ = sent_ - at;
      marks_.erase(marks_.begin(), std::next(it));
    }
  }

  // A refused line is printed with its number; a refused token ends the stream.
  void refusal(const Refused& r) {
    if (r.code == wire::PERMISSION_DENIED) throw r;
    ++refused_;
    ++refused_by_server_;
    std::fprintf(stderr, "irradcast-edit: line %llu: %s\n",
                 static_cast<unsigned long long>(r.request_id), r.what());
  }

  // Poses written since the last answer may be lost with the connection: said, not counted as
  // taken; the next server of the list.
  void next_server(const Lost& lost, const std::string& which) {
    std::fprintf(stderr, "irradcast-edit: %s: %s; %s may be lost; trying the next server\n",
                 session_.server().text().c_str(), lost.what(), which.c_str());
    lost_lines_ += sent_since_answer_;
    sent_since_answer_ = 0;
    marks_.clear();
    session_.connect();
  }

  const Options& o_;
  const std::string& token_;
  Session session_;
  std::map<std::string, Clock::time_point> last_sent_;  // per target
  std::uint64_t line_no_ = 0, sent_ = 0, refused_ = 0, refused_by_server_ = 0;
  // Lines sent since the server last answered (a ping's pong), and those that a lost
  // connection may have taken with it.
  std::uint64_t sent_since_answer_ = 0, answered_ = 0, lost_lines_ = 0, lost_unsent_ = 0;
  const Clock::time_point began_ = Clock::now();
  Clock::time_point last_poll_ = began_, last_mark_ = began_;
  std::map<std::uint64_t, std::uint64_t> marks_;  // sent count at a ping -> its line
};

}  // namespace

// --stream: every line an edit of dynamic nodes (JSON, as --json; blank lines and lines starting
// with '#' are skipped), sent as a streamed pose as soon as it comes, but no more than
// kStreamRate times a second per node (a faster line waits). Refusals name their line; they do
// not stop the stream, except a refused token.
int run_stream(const Options& o, const std::string& token) {
  LineReader reader(o.stream_path);
  PoseStream stream(o, token);
  stream.send_lines(reader);
  return stream.finish();
}

}  // namespace irradcast::edit_tool
