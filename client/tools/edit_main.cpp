// irradcast-edit: sends live scene edits (docs/EDITS.md) to an irradcast-server started with a
// control token. One edit from the command line (JSON or a shorthand flag) or a script of timed
// edits; prints a line per edit once the engine applied it (or, with --no-wait, once the server
// queued it). Exit status: 0 when every edit was accepted, 2 when the server refused the token,
// 1 on any other error (a bad edit: the server's message is printed). With a failover list
// (--connect A,B,...) it connects to the first server that answers, and a connection lost
// between edits moves on to the next; an edit whose answer was cut off is not sent again (edits
// are not idempotent: a move twice moves twice), the error says so. --export FILE.glb writes the
// server's current scene, every edit applied, as glTF 2.0 (the control token is needed too).
// --stream [FILE] sends poses of dynamic nodes as they come, one edit per line
// (docs/DYNAMIC.md#poses). An edit that only moves dynamic nodes makes no revision: it prints
// "poses N applied".
#include <CLI/CLI.hpp>

#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "irradcast/client/backoff.h"
#include "irradcast/client/client_tls.h"
#include "irradcast/client/host_port.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/log.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/blocking_channel.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/scene_package.h"
#include "tool_main.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Options {
  std::string connect;
  irradcast::ClientTls tls;
  std::string token;
  std::string token_file;
  std::string json;
  std::string script;
  std::vector<std::string> move, rotate, scale, show, hide, light_color, light_intensity, albedo,
      emission;
  std::string export_path;  // --export FILE.glb|.gltf
  bool stream = false;      // --stream [FILE]: one edit per line, sent as streamed poses
  std::string stream_path;  // empty: stdin
  bool no_wait = false;
  int timeout_ms = 10000;
  std::string name = "irradcast-edit";
  std::string log_level = "warn";
};

// The connection is gone (refused, reset, closed): another server of the list may do.
using Lost = irradcast::wire::ChannelLost;

// The server answered with an Error frame.
struct Refused : irradcast::Error {
  Refused(irradcast::wire::ErrorCode c, const std::string& message, std::uint64_t request = 0)
      : irradcast::Error(message), code(c), request_id(request) {}
  irradcast::wire::ErrorCode code;
  std::uint64_t request_id;  // the request it answers (0: none)
};

float number(const std::string& text, const std::string& flag) {
  try {
    std::size_t used = 0;
    const float v = std::stof(text, &used);
    if (used == text.size()) return v;
  } catch (const std::exception&) {
  }
  throw irradcast::Error(flag + ": '" + text + "' is not a number");
}

glm::vec3 vec3(const std::string& text, const std::string& flag, bool allow_one = false) {
  std::vector<float> v;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ',')) v.push_back(number(part, flag));
  if (allow_one && v.size() == 1) return glm::vec3(v[0]);
  if (v.size() != 3)
    throw irradcast::Error(flag + ": '" + text + "' must be three numbers X,Y,Z" +
                           (allow_one ? " (or one)" : ""));
  return glm::vec3(v[0], v[1], v[2]);
}

// The edits to send, from exactly one of --json, --script and the shorthand flags.
std::vector<irradcast::EditStep> steps_of(const Options& o) {
  using irradcast::EditOp;
  using Kind = EditOp::Kind;
  std::vector<irradcast::EditStep> steps;
  int sources = 0;
  auto shorthand = [&](const std::vector<std::string>& args, Kind kind, const std::string& flag) {
    if (args.empty()) return;
    ++sources;
    EditOp op;
    op.kind = kind;
    op.target = args[0];
    switch (kind) {
      case Kind::Move:
      case Kind::LightColor:
      case Kind::MaterialAlbedo:
        op.vector = vec3(args.at(1), flag);
        break;
      case Kind::Rotate:
      case Kind::MaterialEmission:
        op.vector = vec3(args.at(1), flag);
        op.value = number(args.at(2), flag);
        break;
      case Kind::Scale:
        op.vector = vec3(args.at(1), flag, true);
        break;
      case Kind::LightIntensity:
        op.value = number(args.at(1), flag);
        break;
      default:
        break;
    }
    irradcast::EditStep step;
    step.edit.ops.push_back(op);
    steps.push_back(step);
  };
  shorthand(o.move, Kind::Move, "--move");
  shorthand(o.rotate, Kind::Rotate, "--rotate");
  shorthand(o.scale, Kind::Scale, "--scale");
  shorthand(o.show, Kind::Show, "--show");
  shorthand(o.hide, Kind::Hide, "--hide");
  shorthand(o.light_color, Kind::LightColor, "--light-color");
  shorthand(o.light_intensity, Kind::LightIntensity, "--light-intensity");
  shorthand(o.albedo, Kind::MaterialAlbedo, "--albedo");
  shorthand(o.emission, Kind::MaterialEmission, "--emission");
  if (!o.json.empty()) {
    ++sources;
    irradcast::EditStep step;
    step.edit = irradcast::parse_edit_json(o.json);
    steps.push_back(step);
  }
  if (!o.script.empty()) {
    ++sources;
    std::ifstream f(o.script);
    if (!f) throw irradcast::Error("--script: cannot read '" + o.script + "'");
    std::ostringstream text;
    text << f.rdbuf();
    steps = irradcast::parse_edit_script(text.str());
  }
  if (o.stream) {
    if (sources != 0 || !o.export_path.empty())
      throw irradcast::Error("--stream reads its edits from a file or stdin: give no other edit");
    return steps;
  }
  if (!o.export_path.empty()) {
    if (sources != 0) throw irradcast::Error("give --export or an edit, not both");
    const std::string ext = std::filesystem::path(o.export_path).extension().string();
    if (ext != ".glb" && ext != ".gltf")
      throw irradcast::Error("--export: '" + o.export_path + "' must end in .glb or .gltf");
    return steps;
  }
  if (sources != 1)
    throw irradcast::Error(
        "give exactly one edit: --json, --script or one shorthand operation (--move, --rotate, "
        "--scale, --show, --hide, --light-color, --light-intensity, --albedo, --emission)");
  return steps;
}

std::string token_of(const Options& o) {
  if (!o.token.empty() && !o.token_file.empty())
    throw irradcast::Error("give --token or --token-file, not both");
  if (!o.token_file.empty()) {
    std::ifstream f(o.token_file);
    if (!f) throw irradcast::Error("--token-file: cannot read '" + o.token_file + "'");
    std::string line;
    std::getline(f, line);
    const char* space = " \t\r\n";
    const std::size_t first = line.find_first_not_of(space);
    if (first == std::string::npos)
      throw irradcast::Error("--token-file: the first line of '" + o.token_file + "' is empty");
    return line.substr(first, line.find_last_not_of(space) + 1 - first);
  }
  return o.token;  // empty: the server will refuse the edit
}

// The server's connection (wire::BlockingChannel) as irradcast-edit reads it: pings answered,
// Error frames thrown.
class Connection {
 public:
  Connection(const irradcast::HostPort& hp, std::chrono::milliseconds timeout,
             const irradcast::ClientTls& tls)
      : channel_(hp.host, hp.port, irradcast::make_tls_context(tls), timeout), timeout_(timeout) {}

  void send(const irradcast::wire::Envelope& e) { channel_.send(e); }

  // The next frame before `deadline` (nullopt on timeout). An Error frame throws Refused, or Lost
  // for one after which the server closes (shutting down, full, idle): another server may do.
  std::optional<irradcast::wire::Envelope> read(Clock::time_point deadline) {
    irradcast::wire::Envelope e;
    while (channel_.read(e, deadline)) {
      if (e.has_error() && irradcast::server_error_is_transient(e.error().code()))
        throw Lost("the server says: " + e.error().message());
      if (e.has_error())
        throw Refused(e.error().code(), e.error().message(), e.error().request_id());
      if (!e.has_ping()) return e;
      irradcast::wire::Envelope pong;
      pong.mutable_pong()->set_nonce(e.ping().nonce());
      pong.mutable_pong()->set_time_us(e.ping().time_us());
      send(pong);
    }
    return std::nullopt;
  }

  // The next frame within the timeout; throws when none comes.
  irradcast::wire::Envelope expect(const std::string& what) {
    auto e = read(Clock::now() + timeout_);
    if (!e)
      throw irradcast::Error("no " + what + " from the server within " +
                             std::to_string(timeout_.count()) + " ms");
    return *e;
  }

  // Waits `ms`, reading (and dropping) frames and pinging so the server's idle timer is happy.
  void wait(double ms, std::chrono::milliseconds ping_every) {
    const auto until =
        Clock::now() + std::chrono::microseconds(static_cast<std::int64_t>(ms * 1e3));
    while (Clock::now() < until) {
      if (Clock::now() - last_send() >= ping_every) {
        irradcast::wire::Envelope p;
        p.mutable_ping()->set_nonce(1);
        send(p);
      }
      read(std::min(until, last_send() + ping_every));
    }
  }

  void close() {
    try {
      send(irradcast::wire::make_bye("edits sent"));
    } catch (const irradcast::Error&) {
    }
    channel_.close();
  }

  std::chrono::milliseconds ping_every{10000};  // a third of the server's idle timeout
  Clock::time_point last_send() const { return channel_.last_send(); }

 private:
  irradcast::wire::BlockingChannel channel_;
  std::chrono::milliseconds timeout_{10000};
};

// A session on one server of the --connect list: Hello, Welcome, and on a lost connection the
// next server.
class Session {
 public:
  Session(const Options& o, std::vector<irradcast::HostPort> servers)
      : o_(o), servers_(std::move(servers)) {
    connect();
  }
  Connection& connection() { return *c_; }
  const irradcast::HostPort& server() const { return servers_[current_]; }

  // The first server that answers, trying each once from the one after the current (the
  // first: from the start of the list). An Error frame that ends the session (server full,
  // shutting down) counts as no answer; every failure is in the error.
  void connect() {
    using namespace irradcast;
    std::string failures;
    for (std::size_t i = 0; i < servers_.size(); ++i) {
      if (c_ || i > 0) current_ = (current_ + 1) % servers_.size();
      c_.reset();
      try {
        c_ = std::make_unique<Connection>(server(), std::chrono::milliseconds(o_.timeout_ms),
                                          tools::tls_of(o_.tls));
        hello();
        return;
      } catch (const Lost& e) {
        failures += "; " + server().text() + ": " + e.what();
      }
    }
    c_.reset();
    throw Error("no server of --connect answered" + failures);
  }

 private:
  void hello() {
    using namespace irradcast;
    wire::Envelope hello;
    hello.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
    hello.mutable_hello()->set_client_name(o_.name);
    c_->send(hello);
    wire::Envelope w = c_->expect("welcome");
    if (!w.has_welcome())
      throw Error(std::string("expected welcome, got ") + wire::message_name(w));
    if (w.welcome().idle_timeout_ms() > 0)
      c_->ping_every =
          std::min(c_->ping_every, std::chrono::milliseconds(w.welcome().idle_timeout_ms() / 3));
    if (servers_.size() > 1) log::info("edit", "connected to " + server().text());
  }

  const Options& o_;
  std::vector<irradcast::HostPort> servers_;
  std::size_t current_ = 0;
  std::unique_ptr<Connection> c_;
};

// Sends one edit and returns its acknowledgement. A connection lost before the edit was written
// moves to the next server and sends it there.
irradcast::wire::SceneEdit send_edit(Session& session, const irradcast::wire::Envelope& e,
                                     std::uint64_t id) {
  using namespace irradcast;
  try {
    session.connection().send(e);
  } catch (const Lost& lost) {
    log::warn("edit", session.server().text() + ": " + lost.what() + "; trying the next server");
    session.connect();
    session.connection().send(e);
  }
  try {
    for (;;) {
      wire::Envelope a = session.connection().expect("acknowledgement");
      if (a.has_scene_edit() && !a.scene_edit().applied() && a.scene_edit().request_id() == id)
        return a.scene_edit();
    }
  } catch (const Lost& lost) {
    throw Error("edit " + std::to_string(id) + ": " + session.server().text() + ": " + lost.what() +
                " before the acknowledgement; the edit may or may not be applied, so it is not "
                "sent again");
  }
}

// --export: the current scene package (SceneExportRequest with the token, then SceneRequest),
// written as glTF 2.0.
int run_export(const Options& o, const std::string& token) {
  using namespace irradcast;
  Session session(o, tools::start_run(o.log_level, o.connect));
  Connection& c = session.connection();
  wire::Envelope request;
  request.mutable_scene_export_request()->set_token(token);
  request.mutable_scene_export_request()->set_request_id(1);
  c.send(request);
  // Other frames (edit broadcasts, pings) may come meanwhile, but not for longer than the
  // timeout altogether.
  const auto deadline = Clock::now() + std::chrono::milliseconds(o.timeout_ms);
  wire::SceneExport answer;
  for (;;) {
    if (Clock::now() > deadline)
      throw Error("no export answer from the server within " + std::to_string(o.timeout_ms) +
                  " ms");
    wire::Envelope a = c.expect("export answer");
    if (a.has_scene_export() && a.scene_export().request_id() == 1) {
      answer = a.scene_export();
      break;
    }
  }
  if (answer.scene_bytes() > wire::kMaxSceneDataBytes)
    throw Error("the server offers a scene package of " + std::to_string(answer.scene_bytes()) +
                " bytes, more than a client takes");
  wire::SceneAssembler assembler(answer.scene_hash(), answer.scene_bytes());
  wire::Envelope get;
  get.mutable_scene_request()->set_offset(0);
  c.send(get);
  while (!assembler.complete()) {
    wire::Envelope a = c.expect("scene chunk");
    if (a.has_scene_chunk()) assembler.add(a.scene_chunk());
  }
  c.close();
  wire::UnpackedScene u = wire::open_scene_package(assembler.bytes(), answer.scene_hash());
  if (answer.poses().poses_size() > 0)  // dynamic nodes where they are now, not as loaded
    apply_edit(u.scene, wire::pose_edit(answer.poses(), u.scene, pose_nodes(u.scene)));
  save_gltf(u.scene, o.export_path);
  std::size_t triangles = 0;
  for (const Mesh& m : u.scene.meshes) triangles += m.triangles.size();
  std::printf("exported revision %llu of %s (%zu nodes, %zu triangles) to %s\n",
              static_cast<unsigned long long>(u.revision), u.scene.name.c_str(),
              u.scene.nodes.size(), triangles, o.export_path.c_str());
  if (u.scene.sky.enabled())
    std::printf(
        "note: glTF has no sky; give irradcast-bake or irradcast-server the sky again "
        "(--sky, --sky-strength, --sun)\n");
  return 0;
}

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

// --stream: every line an edit of dynamic nodes (JSON, as --json; blank lines and lines starting
// with '#' are skipped), sent as a streamed pose as soon as it comes, but no more than
// kStreamRate times a second per node (a faster line waits). Refusals name their line; they do
// not stop the stream, except a refused token.
int run_stream(const Options& o, const std::string& token) {
  using namespace irradcast;
  constexpr auto kGap = std::chrono::microseconds(1000000 / 60);  // PoseBoard::kStreamRate
  LineReader reader(o.stream_path);
  Session session(o, tools::start_run(o.log_level, o.connect));
  std::map<std::string, Clock::time_point> last_sent;  // per target
  std::uint64_t line_no = 0, sent = 0, refused = 0, refused_by_server = 0;
  // Lines sent since the server last answered (a ping's pong), and those that a lost connection
  // may have taken with it.
  std::uint64_t sent_since_answer = 0, answered = 0, lost_lines = 0, lost_unsent = 0;
  const auto began = Clock::now();
  Clock::time_point last_poll = began, last_mark = began;
  constexpr std::uint64_t kMark = std::uint64_t{1} << 62;  // our pings' nonces: kMark | sent
  std::map<std::uint64_t, std::uint64_t> marks;            // sent count at a ping -> its line
  // A refused line is printed with its number; a refused token ends the stream.
  const auto refusal = [&](const Refused& r) {
    if (r.code == wire::PERMISSION_DENIED) throw r;
    ++refused;
    ++refused_by_server;
    std::fprintf(stderr, "irradcast-edit: line %llu: %s\n",
                 static_cast<unsigned long long>(r.request_id), r.what());
  };
  // Reads what the server sent until `until`: refusals are printed, the rest dropped.
  const auto serve = [&](Clock::time_point until) {
    for (;;) {
      try {
        Connection& c = session.connection();
        // A ping every 250 ms while lines go out (and as the idle timeout needs): its pong
        // says the server read every line sent before it.
        if (Clock::now() - last_mark >= std::chrono::milliseconds(250) ||
            Clock::now() - c.last_send() >= c.ping_every) {
          wire::Envelope p;
          p.mutable_ping()->set_nonce(kMark | sent);
          c.send(p);
          marks[sent] = line_no;
          last_mark = Clock::now();
        }
        // A look at the socket at least every 20 ms, so that refusals do not pile up unread,
        // but not a wait for every line of a fast stream.
        const auto now = Clock::now();
        if (until <= now && now - last_poll < std::chrono::milliseconds(20)) return;
        last_poll = now;
        const std::optional<wire::Envelope> a =
            c.read(std::max(until, now + std::chrono::milliseconds(1)));
        if (!a) return;
        if (a->has_pong() && (a->pong().nonce() & kMark)) {
          const std::uint64_t at = a->pong().nonce() & ~kMark;
          if (auto it = marks.find(at); it != marks.end()) {
            answered = it->second;
            sent_since_answer = sent - at;
            marks.erase(marks.begin(), std::next(it));
          }
        }
      } catch (const Refused& r) {
        refusal(r);
      } catch (const Lost& lost) {
        // Poses written since the last answer may be lost with the connection: said, not
        // counted as taken.
        std::fprintf(stderr,
                     "irradcast-edit: %s: %s; poses sent after line %llu may be lost; trying the "
                     "next server\n",
                     session.server().text().c_str(), lost.what(),
                     static_cast<unsigned long long>(answered));
        lost_lines += sent_since_answer;
        sent_since_answer = 0;
        marks.clear();
        session.connect();
        return;
      }
    }
  };
  for (;;) {
    bool ended = false;
    std::optional<std::string> line = reader.next(std::chrono::milliseconds(50), ended);
    if (ended) break;
    if (!line) {
      serve(Clock::now());
      continue;
    }
    ++line_no;
    const std::size_t first = line->find_first_not_of(" \t\r");
    if (first == std::string::npos || (*line)[first] == '#') continue;
    SceneEdit edit;
    try {
      edit = parse_edit_json(*line);
    } catch (const Error& e) {
      ++refused;
      std::fprintf(stderr, "irradcast-edit: line %llu: %s\n",
                   static_cast<unsigned long long>(line_no), e.what());
      continue;
    }
    Clock::time_point at = Clock::now();
    for (const EditOp& op : edit.ops)
      if (auto it = last_sent.find(op.target); it != last_sent.end())
        at = std::max(at, it->second + kGap);
    serve(at);  // waits for the node's rate, serving the connection meanwhile
    wire::Envelope e;
    wire::to_proto(edit, e.mutable_scene_edit());
    e.mutable_scene_edit()->set_token(token);
    e.mutable_scene_edit()->set_request_id(line_no);
    e.mutable_scene_edit()->set_stream(true);
    try {
      session.connection().send(e);
    } catch (const Lost& lost) {
      std::fprintf(stderr,
                   "irradcast-edit: %s: %s; line %llu and those sent after line %llu may be "
                   "lost; trying the next server\n",
                   session.server().text().c_str(), lost.what(),
                   static_cast<unsigned long long>(line_no),
                   static_cast<unsigned long long>(answered));
      lost_lines += sent_since_answer;
      ++lost_unsent;
      sent_since_answer = 0;
      marks.clear();
      session.connect();
      continue;
    }
    ++sent;
    ++sent_since_answer;
    const auto now = Clock::now();
    for (const EditOp& op : edit.ops) last_sent[op.target] = now;
  }
  // Every refusal is in before the answer to a ping sent after the last pose.
  wire::Envelope ping;
  ping.mutable_ping()->set_nonce(0x5157);
  session.connection().send(ping);
  const auto deadline = Clock::now() + std::chrono::milliseconds(o.timeout_ms);
  for (bool ponged = false; !ponged;) {
    std::optional<wire::Envelope> a;
    try {
      a = session.connection().read(deadline);
    } catch (const Refused& r) {
      refusal(r);
      continue;
    }
    if (!a) throw Error("no answer from the server within " + std::to_string(o.timeout_ms) + " ms");
    ponged = a->has_pong() && a->pong().nonce() == 0x5157;
  }
  session.connection().close();
  std::printf("streamed %llu poses from %llu lines in %.2f s, %llu refused, %llu lost\n",
              static_cast<unsigned long long>(sent - refused_by_server - lost_lines),
              static_cast<unsigned long long>(line_no),
              std::chrono::duration<double>(Clock::now() - began).count(),
              static_cast<unsigned long long>(refused),
              static_cast<unsigned long long>(lost_lines));
  return refused == 0 && lost_lines == 0 ? 0 : 1;
}

int run(const Options& o, const std::vector<irradcast::EditStep>& steps, const std::string& token) {
  using namespace irradcast;
  if (!o.export_path.empty()) return run_export(o, token);
  if (o.stream) return run_stream(o, token);
  Session session(o, tools::start_run(o.log_level, o.connect));
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (steps[i].after_ms > 0.0) {
      try {
        Connection& c = session.connection();
        c.wait(steps[i].after_ms, c.ping_every);
      } catch (const Lost& lost) {
        log::warn("edit",
                  session.server().text() + ": " + lost.what() + "; trying the next server");
        session.connect();
      }
    }
    wire::Envelope e;
    wire::SceneEdit* m = e.mutable_scene_edit();
    wire::to_proto(steps[i].edit, m);
    m->set_token(token);
    m->set_request_id(i + 1);
    const auto sent = Clock::now();
    const wire::SceneEdit ack = send_edit(session, e, i + 1);
    const std::uint64_t revision = ack.revision();
    if (revision == 0) {
      // Poses only (docs/DYNAMIC.md#poses): on the viewers' way as acknowledged, no engine work.
      std::printf("poses %llu applied in %.1f ms\n",
                  static_cast<unsigned long long>(ack.pose_sequence()),
                  std::chrono::duration<double, std::milli>(Clock::now() - sent).count());
      std::fflush(stdout);
      continue;
    }
    if (o.no_wait) {
      std::printf("revision %llu queued\n", static_cast<unsigned long long>(revision));
      std::fflush(stdout);
      continue;
    }
    // The broadcast once the engine applied it.
    try {
      for (;;) {
        wire::Envelope a = session.connection().expect("applied edit " + std::to_string(revision));
        if (a.has_scene_edit() && a.scene_edit().applied() && a.scene_edit().revision() >= revision)
          break;
      }
    } catch (const Lost& lost) {
      throw Error("revision " + std::to_string(revision) + " was queued, but " +
                  session.server().text() + ": " + lost.what() + " before it was applied");
    }
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
    std::printf("revision %llu applied in %.1f ms\n", static_cast<unsigned long long>(revision),
                ms);
    std::fflush(stdout);
  }
  session.connection().close();
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "irradcast-edit: sends live scene edits to an irradcast-server started with "
      "--control-token or --control-token-file (docs/EDITS.md). Give one edit: --json, "
      "--script, or one shorthand operation. Prints 'revision N applied in X ms' per edit "
      "(the time from sending it until the server reported it applied), or 'revision N queued' "
      "with --no-wait. Exits 2 when the server refuses the token, 1 on any other error.",
      "irradcast-edit"};
  app.option_defaults()->always_capture_default();
  irradcast::tools::add_connect_flags(app, o.connect, o.tls);
  app.add_option("--token", o.token, "the server's control token");
  app.add_option("--token-file", o.token_file,
                 "read the control token from this file's first line");
  app.add_option(
      "--json", o.json,
      "one edit as JSON: {\"op\": \"move\", \"node\": \"tall_block\", \"by\": [x, y, z]} "
      "or {\"ops\": [...]}");
  app.add_option("--script", o.script,
                 "a JSON array of edits, each with an optional \"after_ms\" delay before it");
  app.add_option("--move", o.move, "NODE X,Y,Z: translate a node")->expected(2);
  app.add_option("--rotate", o.rotate, "NODE AX,AY,AZ DEG: rotate a node about an axis")
      ->expected(3);
  app.add_option("--scale", o.scale, "NODE S or NODE SX,SY,SZ: scale a node")->expected(2);
  app.add_option("--show", o.show, "NODE: show a node and its subtree")->expected(1);
  app.add_option("--hide", o.hide, "NODE: hide a node and its subtree")->expected(1);
  app.add_option("--light-color", o.light_color, "LIGHT R,G,B: a punctual light's colour")
      ->expected(2);
  app.add_option("--light-intensity", o.light_intensity, "LIGHT I: a punctual light's intensity")
      ->expected(2);
  app.add_option("--albedo", o.albedo, "MATERIAL R,G,B: a material's base colour")->expected(2);
  app.add_option("--emission", o.emission, "MATERIAL R,G,B STRENGTH: a material's emission")
      ->expected(3);
  app.add_option("--export", o.export_path,
                 "FILE.glb or FILE.gltf: write the server's current scene (every edit applied) "
                 "as glTF 2.0 instead of editing (needs the token too)");
  app.add_option("--stream", o.stream_path,
                 "[FILE] stream poses of dynamic nodes: one JSON edit per line from FILE or "
                 "stdin, each sent as it comes, at most 60 a second per node; refusals name "
                 "their line (docs/DYNAMIC.md#poses)")
      ->expected(0, 1);
  app.add_flag("--no-wait", o.no_wait, "return once the server queued each edit");
  app.add_option("--timeout-ms", o.timeout_ms, "how long to wait for each answer")
      ->check(CLI::Range(1, 3600000));
  app.add_option("--name", o.name, "client name in the server's logs");
  app.add_option("--log-level", o.log_level, "debug | info | warn | error | off");
  std::vector<irradcast::EditStep> steps;
  std::string token;
  // Exit 2 when the server refuses the token, 1 on any other error.
  auto run_edits = [&]() -> int {
    std::signal(SIGPIPE, SIG_IGN);
    try {
      return run(o, steps, token);
    } catch (const Refused& e) {
      std::fprintf(stderr, "irradcast-edit: %s\n", e.what());
      return e.code == irradcast::wire::PERMISSION_DENIED ? 2 : 1;
    } catch (const irradcast::Error& e) {
      std::fprintf(stderr, "irradcast-edit: %s\n", e.what());
      return 1;
    } catch (const std::exception& e) {
      std::fprintf(stderr, "irradcast-edit: internal error: %s\n", e.what());
      return 1;
    }
  };
  return irradcast::tools::parse_and_run(app, argc, argv, run_edits, [&] {
    o.stream = app.count("--stream") > 0;
    steps = steps_of(o);
    token = token_of(o);
  });
}
