// Poses of dynamic nodes (docs/DYNAMIC.md#poses): the board that coalesces them per node, the
// session that sends the newest and refuses what is hostile or past the rate, the host that keeps
// them out of the revisions and on disk, and irradcast-edit --stream through a real server.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "cli.h"
#include "dynamic_scenes.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/service/pose_board.h"
#include "irradcast/wire/edit_message.h"
#include "irradcast/wire/frame.h"
#include "irradcast/wire/pose_message.h"
#include "service_fixture.h"
#include "session_driver.h"
#include "session_protocol.h"

namespace irradcast::test_poses {

using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

const std::string kToken = "secret-token-for-pose-tests";

NodePoseState at(float x) {
  NodePoseState p;
  p.local[3] = glm::vec4(x, 0.0f, 0.0f, 1.0f);
  return p;
}

wire::Poses decode_poses(const std::string& frame) {
  wire::FrameDecoder d;
  d.feed(frame.data(), frame.size());
  wire::Envelope e;
  EXPECT_EQ(d.next(e), wire::DecodeStatus::Frame);
  EXPECT_TRUE(e.has_poses());
  return e.poses();
}

// The prop's node index in cornell_with_prop (after the box's nodes and the rig).
int prop_node() {
  return static_cast<int>(make_cornell_box().nodes.size()) + 1;
}

}  // namespace

TEST(PoseBoard, CoalescesPerNodeAndEncodesOnceForEverySessionAtTheSameSequence) {
  PoseBoard board;
  int heard = 0;
  board.add_listener([&] { ++heard; });
  EXPECT_EQ(board.frame_since(0, false).frame, nullptr);  // nothing posed, nothing owed
  const PoseBoard::Frame empty = board.frame_since(0, true);
  ASSERT_NE(empty.frame, nullptr);  // the first frame of a session goes even when empty
  EXPECT_TRUE(decode_poses(*empty.frame).complete());
  EXPECT_EQ(decode_poses(*empty.frame).poses_size(), 0);

  EXPECT_EQ(board.post({{4, at(1.0f)}}, 10), 1u);
  EXPECT_EQ(board.post({{4, at(2.0f)}}, 20), 2u);
  EXPECT_EQ(board.post({{9, at(3.0f)}}, 30), 3u);
  EXPECT_EQ(heard, 3);
  // A client at 0 (slow: it missed every post) gets each node once, at its newest pose.
  const PoseBoard::Frame slow = board.frame_since(0, false);
  ASSERT_NE(slow.frame, nullptr);
  EXPECT_EQ(slow.sequence, 3u);
  const wire::Poses p = decode_poses(*slow.frame);
  ASSERT_EQ(p.poses_size(), 2);
  EXPECT_EQ(p.poses(0).node(), 4u);
  EXPECT_FLOAT_EQ(p.poses(0).matrix(12), 2.0f);
  EXPECT_EQ(p.poses(1).node(), 9u);
  EXPECT_EQ(p.sequence(), 3u);
  EXPECT_EQ(p.posed_us(), 30u);
  EXPECT_FALSE(p.complete());
  // Encoded once for every session at the same point.
  EXPECT_EQ(board.frame_since(0, false).frame, slow.frame);
  // A client at 2 gets node 9 only; one at 3 nothing.
  const wire::Poses recent = decode_poses(*board.frame_since(2, false).frame);
  ASSERT_EQ(recent.poses_size(), 1);
  EXPECT_EQ(recent.poses(0).node(), 9u);
  EXPECT_EQ(board.frame_since(3, false).frame, nullptr);
  // The complete frame holds every posed node.
  EXPECT_EQ(decode_poses(*board.frame_since(3, true).frame).poses_size(), 2);
}

// A gateway's copy of an origin that restarted without some poses: the whole set replaced, and
// every session's next frame complete (the client puts the missing nodes back).
TEST(PoseBoard, AReplacedSetIsSentWholeToEveryClient) {
  PoseBoard board;
  board.post({{4, at(1.0f)}, {9, at(2.0f)}}, 10);
  const std::uint64_t seen = board.sequence();
  EXPECT_EQ(board.replace({{9, at(3.0f)}}, 20), seen + 1);
  const wire::Poses p = decode_poses(*board.frame_since(seen, false).frame);
  EXPECT_TRUE(p.complete());
  ASSERT_EQ(p.poses_size(), 1);
  EXPECT_EQ(p.poses(0).node(), 9u);
  EXPECT_FLOAT_EQ(p.poses(0).matrix(12), 3.0f);
  EXPECT_EQ(board.snapshot().size(), 1u);
  // After it, deltas again.
  board.post({{9, at(4.0f)}}, 30);
  EXPECT_FALSE(decode_poses(*board.frame_since(seen + 1, false).frame).complete());
}

TEST(PoseBoard, AStreamPastItsRateIsRefusedAndRefillsAtTheRate) {
  PoseBoard board;
  const auto t0 = PoseBoard::Clock::now();
  int passed = 0;
  for (int i = 0; i < 30; ++i) passed += board.admit_stream({1}, t0) ? 0 : 1;
  EXPECT_EQ(passed, static_cast<int>(PoseBoard::kStreamBurst));
  EXPECT_EQ(board.admit_stream({1}, t0), std::optional<int>(1));
  // Another node has its own rate; a pose of two nodes takes from both or from neither.
  EXPECT_EQ(board.admit_stream({2}, t0), std::nullopt);
  EXPECT_EQ(board.admit_stream({2, 1}, t0), std::optional<int>(1));
  // One period later, one more.
  const auto t1 = t0 + std::chrono::microseconds(static_cast<int>(1e6 / PoseBoard::kStreamRate));
  EXPECT_EQ(board.admit_stream({1}, t1 + 10us), std::nullopt);
  EXPECT_EQ(board.admit_stream({1}, t1 + 20us), std::optional<int>(1));
  // Over one second a steady stream gets kStreamRate through, give or take the burst.
  int steady = 0;
  const auto t2 = t1 + 1s;
  for (int i = 0; i < 600; ++i)
    steady += board.admit_stream({3}, t2 + std::chrono::milliseconds(i * 1000 / 600)) ? 0 : 1;
  EXPECT_NEAR(steady, PoseBoard::kStreamRate + PoseBoard::kStreamBurst, 2.0);
}

// Sessions over a real host with a dynamic prop, without sockets (as test_session_protocol).
class PoseSessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Progress::set_enabled(false);
    log::set_level(log::Level::Warn);
    host.emplace(test::cornell_with_prop(), "cornell", test::quick_host(1));
    host->step();
    options.control_token = kToken;
    context.emplace(SessionContext{*host, options, counters, peers, [] { return ServerStats{}; },
                                   options.max_hello_frame});
    // As the server does: every session hears of new poses.
    host->poses()->add_listener([this] {
      for (const auto& s : sessions) s->poses_changed();
    });
  }

  SessionProtocol& session(bool subscribed) {
    sessions.push_back(test::joined(*context, sessions.size() + 1, subscribed));
    SessionProtocol& s = *sessions.back();
    written(s);  // the Welcome, the tiles, the first Poses
    return s;
  }

  static void feed(SessionProtocol& s, const wire::Envelope& e) { test::feed(s, e); }
  // Everything the session writes now, tiles left out.
  static std::vector<wire::Envelope> written(SessionProtocol& s) {
    return test::frames_written(s, [](const wire::Envelope& e) { return !e.has_tile_update(); });
  }

  static wire::Envelope pose(const std::string& json, std::uint64_t id, bool stream = true,
                             const std::string& token = kToken) {
    wire::Envelope e;
    wire::to_proto(parse_edit_json(json), e.mutable_scene_edit());
    e.mutable_scene_edit()->set_token(token);
    e.mutable_scene_edit()->set_request_id(id);
    e.mutable_scene_edit()->set_stream(stream);
    return e;
  }

  // The prop's local x on the board (nullopt: not posed).
  std::optional<float> board_x() {
    const auto poses = host->poses()->snapshot();
    const auto it = poses.find(prop_node());
    if (it == poses.end()) return std::nullopt;
    return it->second.local[3].x;
  }

  std::optional<EngineHost> host;
  ServerOptions options;
  ServerCounters counters;
  PeerTable peers{options};
  std::optional<SessionContext> context;
  std::vector<std::unique_ptr<SessionProtocol>> sessions;
};

TEST_F(PoseSessionTest, AStreamedPoseReachesEverySubscribedViewerAndNoRevisionIsMade) {
  SessionProtocol& editor = session(false);
  SessionProtocol& viewer = session(true);
  const std::uint64_t revision = host->revision();
  feed(editor, pose(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})", 5));
  EXPECT_TRUE(written(editor).empty()) << "a streamed pose is not acknowledged";
  const std::vector<wire::Envelope> out = written(viewer);
  ASSERT_EQ(out.size(), 1u);
  ASSERT_TRUE(out[0].has_poses());
  ASSERT_EQ(out[0].poses().poses_size(), 1);
  EXPECT_EQ(out[0].poses().poses(0).node(), static_cast<std::uint32_t>(prop_node()));
  EXPECT_FLOAT_EQ(out[0].poses().poses(0).matrix(12), 0.1f);
  EXPECT_EQ(host->revision(), revision);
  EXPECT_EQ(host->submit_edit(test::move("tall_block", {0.01f, 0.0f, 0.0f})), revision + 1);
  // An edit (not streamed) of poses only is acknowledged with its pose sequence, revision 0.
  feed(editor, pose(R"({"op": "hide", "node": "prop"})", 6, false));
  const std::vector<wire::Envelope> ack = written(editor);
  ASSERT_EQ(ack.size(), 1u);
  ASSERT_TRUE(ack[0].has_scene_edit());
  EXPECT_EQ(ack[0].scene_edit().request_id(), 6u);
  EXPECT_EQ(ack[0].scene_edit().revision(), 0u);
  EXPECT_EQ(ack[0].scene_edit().pose_sequence(), 2u);
  const std::vector<wire::Envelope> hidden = written(viewer);
  ASSERT_EQ(hidden.size(), 1u);
  EXPECT_TRUE(hidden[0].poses().poses(0).hidden());
  // A session that joins now gets every posed node in its first, complete Poses.
  SessionProtocol& late = *sessions.emplace_back(
      std::make_unique<SessionProtocol>(*context, 9, "10.0.0.2", "10.0.0.2:5000"));
  wire::Envelope h;
  h.mutable_hello()->set_protocol_version(wire::kProtocolVersion);
  feed(late, h);
  wire::Envelope sub;
  sub.mutable_subscribe()->set_all(true);
  feed(late, sub);
  int complete = 0;
  for (const wire::Envelope& e : written(late))
    if (e.has_poses()) {
      ++complete;
      EXPECT_TRUE(e.poses().complete());
      ASSERT_EQ(e.poses().poses_size(), 1);
      EXPECT_TRUE(e.poses().poses(0).hidden());
      EXPECT_FLOAT_EQ(e.poses().poses(0).matrix(12), 0.1f);
    }
  EXPECT_EQ(complete, 1);
}

TEST_F(PoseSessionTest, ASlowViewerGetsTheNewestPoseNeverAQueue) {
  SessionProtocol& editor = session(false);
  SessionProtocol& viewer = session(true);
  // The burst of streamed poses, then 190 more posted to the board while the viewer writes
  // nothing (its socket is full).
  for (int i = 1; i <= 10; ++i)
    feed(editor, pose(R"({"op": "move", "node": "prop", "by": [0.001, 0, 0]})", i));
  EXPECT_TRUE(written(editor).empty());
  ASSERT_EQ(host->poses()->sequence(), 10u);
  for (int i = 11; i <= 200; ++i) host->poses()->post({{prop_node(), at(0.001f * i)}}, i);
  const std::vector<wire::Envelope> out = written(viewer);
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].poses().poses_size(), 1);
  EXPECT_NEAR(out[0].poses().poses(0).matrix(12), 0.2f, 1e-5f);
  EXPECT_EQ(out[0].poses().sequence(), 200u);
  EXPECT_TRUE(written(viewer).empty());
}

TEST_F(PoseSessionTest, HostilePosesGetClearErrorsAndLeaveNothingBehind) {
  SessionProtocol& editor = session(false);
  SessionProtocol& viewer = session(true);
  const auto refused = [&](const wire::Envelope& e, wire::ErrorCode code, const std::string& says) {
    feed(editor, e);
    const std::vector<wire::Envelope> out = written(editor);
    ASSERT_EQ(out.size(), 1u) << says;
    ASSERT_TRUE(out[0].has_error()) << says;
    EXPECT_EQ(out[0].error().code(), code) << out[0].error().message();
    EXPECT_EQ(out[0].error().request_id(), e.scene_edit().request_id());
    EXPECT_NE(out[0].error().message().find(says), std::string::npos) << out[0].error().message();
  };
  wire::Envelope nan = pose(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})", 1);
  nan.mutable_scene_edit()->mutable_ops(0)->mutable_vector()->set_y(
      std::numeric_limits<float>::quiet_NaN());
  refused(nan, wire::BAD_REQUEST, "not finite");
  refused(pose(R"({"op": "move", "node": "prop", "by": [1e30, 0, 0]})", 2), wire::BAD_REQUEST,
          "beyond");
  refused(pose(R"({"op": "move", "node": "no_such_node", "by": [0.1, 0, 0]})", 3),
          wire::BAD_REQUEST, "no_such_node");
  refused(pose(R"({"op": "move", "node": "tall_block", "by": [0.1, 0, 0]})", 4), wire::BAD_REQUEST,
          "a streamed pose moves, shows or hides dynamic nodes only");
  refused(pose(R"({"op": "albedo", "material": "#0", "color": [1, 0, 0]})", 5), wire::BAD_REQUEST,
          "dynamic nodes only");
  // A mixed stream is refused whole: the dynamic op did not pass either.
  refused(pose(R"({"ops": [{"op": "move", "node": "prop", "by": [0.1, 0, 0]},
                           {"op": "move", "node": "tall_block", "by": [0.1, 0, 0]}]})",
               6),
          wire::BAD_REQUEST, "tall_block");
  EXPECT_EQ(host->poses()->sequence(), 0u);
  EXPECT_EQ(board_x(), std::nullopt);
  EXPECT_TRUE(written(viewer).empty());
  // A flood: the burst passes, the rest is refused one by one, naming the node and the rate.
  int passed = 0, limited = 0;
  for (int i = 0; i < 40; ++i) {
    feed(editor, pose(R"({"op": "move", "node": "prop", "by": [0.001, 0, 0]})", 100 + i));
    for (const wire::Envelope& e : written(editor)) {
      ASSERT_TRUE(e.has_error());
      EXPECT_EQ(e.error().code(), wire::RATE_LIMITED);
      EXPECT_EQ(e.error().request_id(), 100u + i);
      EXPECT_NE(e.error().message().find("'prop' is posed more than 60 times a second"),
                std::string::npos)
          << e.error().message();
      ++limited;
    }
  }
  passed = 40 - limited;
  EXPECT_GE(passed, static_cast<int>(PoseBoard::kStreamBurst));
  EXPECT_LE(passed, static_cast<int>(PoseBoard::kStreamBurst) + 2);  // refilled meanwhile
  EXPECT_EQ(host->poses()->sequence(), static_cast<std::uint64_t>(passed));
  // Only what passed moved the prop, and the session is still open and served.
  ASSERT_TRUE(board_x().has_value());
  EXPECT_NEAR(*board_x(), 0.001f * passed, 1e-6f);
  EXPECT_FALSE(editor.closing());
  EXPECT_FALSE(editor.closed());
  EXPECT_EQ(counters.poses_streamed.load(), static_cast<std::uint64_t>(passed));
  EXPECT_EQ(counters.poses_refused.load(), static_cast<std::uint64_t>(limited) + 6);
  // A wrong token: refused like any edit, nothing posed.
  feed(editor, pose(R"({"op": "move", "node": "prop", "by": [0.1, 0, 0]})", 200, true, "nope"));
  EXPECT_EQ(host->poses()->sequence(), static_cast<std::uint64_t>(passed));
}

TEST(Poses, ClientsRefuseHostilePoses) {
  const Scene scene = test::cornell_with_prop();
  wire::Poses m;
  *m.add_poses() =
      wire::node_pose_to_proto(static_cast<std::uint32_t>(prop_node()), glm::mat4(1.0f), true);
  EXPECT_EQ(wire::pose_edit(m, scene, pose_nodes(scene)).ops.size(), 2u);
  const auto refuses = [&](const wire::Poses& bad, const std::string& says) {
    try {
      wire::pose_edit(bad, scene, pose_nodes(scene));
      ADD_FAILURE() << "taken: " << says;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  };
  wire::Poses out_of_range = m;
  out_of_range.mutable_poses(0)->set_node(100000);
  refuses(out_of_range, "names node 100000 of a scene of");
  wire::Poses static_node = m;
  static_node.mutable_poses(0)->set_node(0);
  refuses(static_node, "which is not dynamic");
  wire::Poses short_matrix = m;
  short_matrix.mutable_poses(0)->mutable_matrix()->RemoveLast();
  refuses(short_matrix, "has 15 matrix values");
}

// With a state folder, poses survive the server: an edit's before it is acknowledged, streamed
// ones within kPoseSaveInterval (and at a clean stop).
TEST(Poses, SurviveARestartWithTheStateFolder) {
  const fs::path dir = fs::path(::testing::TempDir()) / "poses_restart";
  fs::remove_all(dir);
  EngineHostOptions o = test::quick_host(1);
  o.state_dir = dir.string();
  {
    EngineHost host(test::cornell_with_prop(), "cornell", o);
    EXPECT_EQ(host.submit(test::move("prop", {0.25f, 0.0f, 0.0f}), false).pose_sequence, 1u);
    EXPECT_TRUE(fs::exists(dir / PoseFile::kFileName)) << "on disk before the acknowledgement";
    for (int i = 0; i < 3; ++i) host.submit(test::move("prop", {0.0f, 0.01f, 0.0f}), true);
    EXPECT_EQ(host.submit_edit(test::move("tall_block", {0.01f, 0.0f, 0.0f})), 1u);
  }
  {
    EngineHost host(test::cornell_with_prop(), "cornell", o);
    EXPECT_EQ(host.revision(), 1u);
    std::uint64_t sequence = 0;
    const auto poses = host.poses()->snapshot(&sequence);
    EXPECT_EQ(sequence, 4u);
    ASSERT_EQ(poses.count(prop_node()), 1u);
    EXPECT_FLOAT_EQ(poses.at(prop_node()).local[3].x, 0.25f);
    EXPECT_NEAR(poses.at(prop_node()).local[3].y, 0.03f, 1e-6f);
    // The validation scene has them too: a relative move goes on from there.
    host.submit(test::move("prop", {0.05f, 0.0f, 0.0f}), false);
    EXPECT_FLOAT_EQ(host.poses()->snapshot().at(prop_node()).local[3].x, 0.3f);
    EXPECT_EQ(host.poses()->sequence(), 5u);
  }
  // A damaged file, another scene's: clear errors, never a silent start without them.
  std::ofstream(dir / PoseFile::kFileName, std::ios::binary | std::ios::trunc) << "garbage!";
  try {
    EngineHost host(test::cornell_with_prop(), "cornell", o);
    ADD_FAILURE() << "a damaged pose file was taken";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("is damaged"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("move it away"), std::string::npos) << e.what();
  }
  fs::remove_all(dir);
}

// irradcast-edit --stream against a real server: the lines become poses the viewer shows; a
// line on a static node or of bad JSON is refused by its line number, the rest go on.
TEST(Poses, IrradcastEditStreamsLinesToTheViewers) {
  const fs::path dir = fs::path(::testing::TempDir()) / "poses_stream";
  fs::remove_all(dir);
  fs::create_directories(dir);
  EngineHost host(test::cornell_with_prop(), "cornell", test::quick_host(1));
  host.start();
  ServerOptions so = test::loopback();
  so.control_token = kToken;
  Server server(host, so);
  server.start();
  ViewClient viewer(test::client_of(server, "viewer"));
  viewer.connect();
  {
    std::ofstream lines(dir / "poses.jsonl");
    lines << "# a prop walks along x\n";
    for (int i = 1; i <= 30; ++i)
      lines << R"({"op": "transform", "node": "prop", "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, )"
            << 0.01 * i << ", 0, 0, 1]}\n";
    lines << R"({"op": "move", "node": "tall_block", "by": [0.1, 0, 0]})"
          << "\n";
    lines << "{not json\n";
  }
  const auto began = std::chrono::steady_clock::now();
  const test::CliResult r = test::run_cli(
      IRRADCAST_EDIT_EXE, "--connect 127.0.0.1:" + std::to_string(server.port()) + " --token " +
                              kToken + " --stream " + (dir / "poses.jsonl").string());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - began).count();
  EXPECT_EQ(r.status, 1) << r.output;  // two lines refused
  EXPECT_NE(r.output.find("streamed 30 poses from 33 lines"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("2 refused"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("line 32: edit op 1 (move): a streamed pose moves"), std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("line 33:"), std::string::npos) << r.output;
  // 30 poses of one node at no more than 60 a second: half a second at least.
  EXPECT_GE(seconds, 29.0 / 60.0);
  EXPECT_EQ(host.poses()->sequence(), 30u);
  EXPECT_EQ(host.revision(), 0u);
  EXPECT_TRUE(test::eventually([&] {
    viewer.poll(20ms);
    return viewer.pose_sequence() >= 30u;
  }));
  EXPECT_NEAR(viewer.scene().nodes[static_cast<std::size_t>(prop_node())].local[3].x, 0.3f, 1e-5f);
  viewer.close();
  server.stop();
  host.stop();
  fs::remove_all(dir);
}

}  // namespace irradcast::test_poses
