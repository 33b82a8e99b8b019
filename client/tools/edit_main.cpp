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
#include "irradcast/common/cli.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "edit_session.h"
#include "irradcast/client/backoff.h"
#include "irradcast/client/host_port.h"
#include "irradcast/common/error.h"
#include "irradcast/common/gltf.h"
#include "irradcast/common/log.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "irradcast/wire/scene_package.h"
#include "tool_main.h"

using irradcast::edit_tool::Options;

namespace {

using irradcast::edit_tool::Clock;
using irradcast::edit_tool::Connection;
using irradcast::edit_tool::Lost;
using irradcast::edit_tool::Refused;
using irradcast::edit_tool::Session;

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
