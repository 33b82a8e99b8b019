// The durable edit journal (edit_journal.h) on its own and under an EngineHost: edits appended
// and read back in order, a torn or corrupt tail cut off, another scene refused, a second server
// on the same folder refused, compaction to one snapshot (state_edit), sky maps kept exactly, and
// a host restarted on the same folder at the same revision and scene package.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "cli.h"
#include "irradcast/client/view_client.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/edit_journal.h"
#include "irradcast/service/engine_host.h"
#include "irradcast/wire/scene_package.h"
#include "process.h"
#include "service_fixture.h"

namespace irradcast::test_edit_journal {
namespace {

namespace fs = std::filesystem;

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::path(::testing::TempDir()) / ("journal_" + name);
  fs::remove_all(d);
  return d;
}

EditJournalOptions options(const fs::path& dir, const std::string& hash = std::string(32, 'a')) {
  EditJournalOptions o;
  o.dir = dir;
  o.scene_id = "test";
  o.scene_hash = hash;
  o.compact_after = 0;
  return o;
}

SceneEdit json_edit(const std::string& text) {
  return parse_edit_json(text);
}

const char* const kEdits[] = {
    R"({"op": "move", "node": "tall_block", "by": [0.05, 0, 0]})",
    R"({"op": "albedo", "material": "red", "color": [0.1, 0.2, 0.7]})",
    R"({"op": "emission", "material": "light", "color": [1, 0.5, 0.25], "strength": 3})",
    R"({"op": "hide", "node": "short_block"})",
};

std::string json_of(const SceneEdit& e) {
  return edit_to_json(e);
}

TEST(EditJournal, AppendedEditsAreReadBackInOrder) {
  const fs::path dir = fresh_dir("order");
  {
    EditJournal j(options(dir));
    EXPECT_TRUE(j.entries().empty());
    for (std::uint64_t r = 1; r <= 4; ++r) j.append(r, json_edit(kEdits[r - 1]));
    EXPECT_EQ(j.records(), 4u);
    EXPECT_THROW(j.append(7, json_edit(kEdits[0])), Error);  // revisions go up by one
  }
  EditJournal j(options(dir));
  ASSERT_EQ(j.entries().size(), 4u);
  EXPECT_EQ(j.replay_revision(), 4u);
  EXPECT_EQ(j.cut_bytes(), 0u);
  for (std::size_t i = 0; i < 4; ++i) {
    EXPECT_EQ(j.entries()[i].revision, i + 1);
    EXPECT_FALSE(j.entries()[i].snapshot);
    EXPECT_EQ(json_of(j.entries()[i].edit), json_of(json_edit(kEdits[i])));
  }
}

TEST(EditJournal, AnotherSceneIsAClearErrorNamingBothHashes) {
  const fs::path dir = fresh_dir("scene");
  { EditJournal j(options(dir, std::string(32, 'a'))); }
  try {
    EditJournal j(options(dir, std::string(32, 'b')));
    FAIL() << "opened another scene's journal";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(wire::hex(std::string(32, 'a'))), std::string::npos) << m;
    EXPECT_NE(m.find(wire::hex(std::string(32, 'b'))), std::string::npos) << m;
    EXPECT_NE(m.find("--state-dir"), std::string::npos) << m;
  }
}

TEST(EditJournal, ASecondServerOnTheSameFolderIsRefused) {
  const fs::path dir = fresh_dir("lock");
  EditJournal first(options(dir));
  try {
    EditJournal second(options(dir));
    FAIL() << "two journals on one folder";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("another irradcast-server"), std::string::npos)
        << e.what();
  }
}

TEST(EditJournal, NotAJournalIsRefusedAndLeftAlone) {
  const fs::path dir = fresh_dir("foreign");
  fs::create_directories(dir);
  std::ofstream(dir / EditJournal::kFileName) << "some file of the operator's\n";
  EXPECT_THROW({ EditJournal j(options(dir)); }, Error);
  std::ifstream in(dir / EditJournal::kFileName);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "some file of the operator's");
}

// The journal with 3 edits; returns its size after 2 and after 3.
std::pair<std::uintmax_t, std::uintmax_t> three_edits(const fs::path& dir) {
  EditJournal j(options(dir));
  j.append(1, json_edit(kEdits[0]));
  j.append(2, json_edit(kEdits[1]));
  const std::uintmax_t two = fs::file_size(j.path());
  j.append(3, json_edit(kEdits[2]));
  return {two, fs::file_size(j.path())};
}

TEST(EditJournal, ATornTailIsCutOffAndTheJournalGoesOn) {
  const fs::path dir = fresh_dir("torn");
  const auto [two, three] = three_edits(dir);
  // Power lost in the middle of the third record's write.
  fs::resize_file(dir / EditJournal::kFileName, three - 5);
  {
    EditJournal j(options(dir));
    ASSERT_EQ(j.entries().size(), 2u);
    EXPECT_EQ(j.replay_revision(), 2u);
    EXPECT_EQ(j.cut_bytes(), three - 5 - two);
    EXPECT_EQ(fs::file_size(j.path()), two);
    j.append(3, json_edit(kEdits[3]));
  }
  EditJournal j(options(dir));
  ASSERT_EQ(j.entries().size(), 3u);
  EXPECT_EQ(j.cut_bytes(), 0u);
  EXPECT_EQ(json_of(j.entries()[2].edit), json_of(json_edit(kEdits[3])));
}

TEST(EditJournal, ACorruptRecordOrAGarbageLengthEndsTheJournalThere) {
  const fs::path dir = fresh_dir("corrupt");
  const auto [two, three] = three_edits(dir);
  {  // A byte of the third record's payload flipped.
    std::fstream f(dir / EditJournal::kFileName, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(three - 3));
    const char c = static_cast<char>(f.get());
    f.seekp(static_cast<std::streamoff>(three - 3));
    f.put(static_cast<char>(c ^ 0x40));
  }
  {
    EditJournal j(options(dir));
    EXPECT_EQ(j.entries().size(), 2u);
    EXPECT_EQ(fs::file_size(j.path()), two);
  }
  {  // A length of 4 GiB - 1 and a little garbage: no allocation of that size, cut off.
    std::ofstream f(dir / EditJournal::kFileName, std::ios::app | std::ios::binary);
    f << std::string("\xff\xff\xff\xff", 4) << std::string(40, 'x');
  }
  EditJournal j(options(dir));
  EXPECT_EQ(j.entries().size(), 2u);
  EXPECT_EQ(j.cut_bytes(), 44u);
}

TEST(EditJournal, SkyMapsAreKeptExactly) {
  const fs::path dir = fresh_dir("sky");
  auto map = std::make_shared<ImageRGB>(8, 4);
  for (std::size_t i = 0; i < map->pixels.size(); ++i)
    map->pixels[i] = glm::vec3(0.001f * static_cast<float>(i) + 1e-7f, 3.14159f, 70000.5f);
  SceneEdit e;
  EditOp& op = e.ops.emplace_back();
  op.kind = EditOp::Kind::Sky;
  op.sky_parts = EditOp::kSkyFile | EditOp::kSkyStrength;
  op.target = "dusk.exr";
  op.value = 2.0f;
  op.sky_map = map;
  { EditJournal(options(dir)).append(1, e); }
  EditJournal j(options(dir));
  ASSERT_EQ(j.entries().size(), 1u);
  const EditOp& back = j.entries()[0].edit.ops.at(0);
  ASSERT_TRUE(back.sky_map);
  EXPECT_EQ(back.sky_map->width, 8);
  EXPECT_EQ(back.sky_map->pixels, map->pixels);  // bit for bit, not the viewers' RGB9E5 copy
  EXPECT_EQ(back.target, "dusk.exr");
  EXPECT_EQ(back.value, 2.0f);
}

TEST(StateEdit, TakesTheLoadedSceneToTheEditedState) {
  const Scene loaded = make_cornell_box();
  Scene edited = loaded;
  EXPECT_TRUE(state_edit(loaded, edited).ops.empty());
  for (const char* text : kEdits) apply_edit(edited, json_edit(text));
  apply_edit(edited, json_edit(R"({"op": "move", "node": "tall_block", "by": [0, 0.1, 0]})"));
  apply_edit(edited, json_edit(R"({"op": "sky", "color": [0.1, 0.2, 0.3], "strength": 2})"));
  const SceneEdit snapshot = state_edit(loaded, edited);
  // One op per changed thing: the transform once, not twice.
  EXPECT_EQ(snapshot.ops.size(), 5u) << edit_to_json(snapshot);
  Scene replayed = loaded;
  apply_edit(replayed, snapshot);
  for (std::size_t i = 0; i < edited.nodes.size(); ++i) {
    EXPECT_EQ(replayed.nodes[i].local, edited.nodes[i].local) << i;
    EXPECT_EQ(replayed.nodes[i].visible, edited.nodes[i].visible) << i;
  }
  for (std::size_t i = 0; i < edited.materials.size(); ++i) {
    EXPECT_EQ(replayed.materials[i].base_color, edited.materials[i].base_color) << i;
    EXPECT_EQ(replayed.materials[i].emission(), edited.materials[i].emission()) << i;
  }
  EXPECT_EQ(replayed.sky.color, edited.sky.color);
  EXPECT_EQ(replayed.sky.strength, edited.sky.strength);
  EXPECT_TRUE(state_edit(replayed, edited).ops.empty());
  Scene other = load_scene("rooms:1");
  EXPECT_THROW(state_edit(loaded, other), Error);
}

// A host with a state folder: its edits survive it (a host built again on the same scene and
// folder starts at the same revision with the same scene package), with and without compaction.
void host_restart(std::uint32_t compact_after, const std::string& name) {
  const fs::path dir = fresh_dir(name);
  EngineHostOptions o = test::quick_host(1);
  o.state_dir = dir.string();
  o.journal_compact_after = compact_after;
  std::string hash;
  {
    EngineHost host(make_cornell_box(), "cornell", o);
    for (const char* text : kEdits) host.submit_edit(json_edit(text));
    host.step();
    EXPECT_EQ(host.revision(), 4u);
    hash = host.package()->hash;
  }
  EngineHost again(make_cornell_box(), "cornell", o);
  EXPECT_EQ(again.revision(), 4u);
  EXPECT_EQ(again.stats().revision, 4u);
  EXPECT_EQ(again.package()->hash, hash);
  EXPECT_EQ(wire::open_scene_package(again.package()->bytes, hash).revision, 4u);
  // It goes on from there.
  EXPECT_EQ(again.submit_edit(json_edit(R"({"op": "show", "node": "short_block"})")), 5u);
  again.step();
  EXPECT_EQ(again.revision(), 5u);
}

TEST(EditJournal, AHostStartedAgainOnTheFolderHasItsEdits) {
  host_restart(0, "host");
}

TEST(EditJournal, AHostStartedAgainAfterCompactionHasItsEdits) {
  host_restart(2, "host_compact");
  // Compacted at revisions 2 and 4: the file holds a snapshot of revision 4 and the fifth edit.
  const fs::path dir = fs::path(::testing::TempDir()) / "journal_host_compact";
  EditJournal j(options(dir, wire::scene_content_hash(make_cornell_box())));
  ASSERT_EQ(j.entries().size(), 2u);
  EXPECT_TRUE(j.entries()[0].snapshot);
  EXPECT_EQ(j.entries()[0].revision, 4u);
  EXPECT_EQ(j.entries()[0].edit.ops.size(), 4u) << edit_to_json(j.entries()[0].edit);
  EXPECT_EQ(j.entries()[1].revision, 5u);
}

// Two scales by 0.001 are each a valid edit, but together they make a transform that one
// absolute op may not set (its determinant is below the edits' bound): a snapshot of it would not
// replay, so that compaction is skipped and the edits stay in the journal as they came.
TEST(EditJournal, ASnapshotThatWouldNotReplayIsNotWritten) {
  const fs::path dir = fresh_dir("singular");
  EngineHostOptions o = test::quick_host(1);
  o.state_dir = dir.string();
  o.journal_compact_after = 1;
  const char* scale = R"({"op": "scale", "node": "tall_block", "by": 0.001})";
  std::string hash;
  {
    EngineHost host(make_cornell_box(), "cornell", o);
    host.submit_edit(json_edit(scale));  // compacted: a snapshot of one scale replays
    host.submit_edit(json_edit(scale));  // not compacted
    host.step();
    EXPECT_EQ(host.revision(), 2u);
    hash = host.package()->hash;
  }
  {
    EditJournal j(options(dir, wire::scene_content_hash(make_cornell_box())));
    ASSERT_EQ(j.entries().size(), 2u);
    EXPECT_TRUE(j.entries()[0].snapshot);
    EXPECT_FALSE(j.entries()[1].snapshot);
  }
  EngineHost again(make_cornell_box(), "cornell", o);
  EXPECT_EQ(again.revision(), 2u);
  EXPECT_EQ(again.package()->hash, hash);
}

TEST(EditJournal, AHostOnAnotherSceneIsRefused) {
  const fs::path dir = fresh_dir("host_other");
  EngineHostOptions o = test::quick_host(1);
  o.state_dir = dir.string();
  { EngineHost host(make_cornell_box(), "cornell", o); }
  try {
    EngineHost other(load_scene("rooms:1"), "rooms:1", o);
    FAIL() << "a journal of cornell replayed on rooms:1";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cornell"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("rooms:1"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace irradcast::test_edit_journal

// The acceptance case as a user meets it: irradcast-server --state-dir, four edits through
// irradcast-edit (a move, an albedo, an emission, a hide), then kill -9 and a restart, then
// SIGINT and a restart: every time the server comes back at revision 4 with the same scene
// package (a viewer's cached package stays valid), and takes edit 5 after it.
namespace irradcast::test_edit_journal {
namespace {

using namespace std::chrono_literals;

std::unique_ptr<test::Process> start_server(std::uint16_t port, const fs::path& dir,
                                            const fs::path& token, const std::string& log) {
  auto p = std::make_unique<test::Process>(
      test::command(IRRADCAST_SERVER_EXE,
                    "--scene cornell --bind 127.0.0.1 --port " + std::to_string(port) +
                        " --texels-per-scene 32 --tile-size 16 --max-updates 1 --threads 1 "
                        "--io-threads 1 --log-level info --state-dir " +
                        dir.string() + " --control-token-file " + token.string()),
      fs::path(::testing::TempDir()) / log);
  return p;
}

// The revision and package hash a new viewer gets.
std::pair<std::uint64_t, std::string> viewer_sees(std::uint16_t port) {
  ViewClientOptions vo;
  vo.port = port;
  vo.name = "journal-viewer";
  vo.connect_timeout = 30000ms;
  ViewClient v(vo);
  v.connect();
  auto r = std::make_pair(v.scene_revision(), v.scene_hash());
  v.close();
  return r;
}

TEST(EditJournal, EditsSurviveKill9AndSigintOfIrradcastServer) {
  const fs::path dir = fresh_dir("server");
  const fs::path token = fs::path(::testing::TempDir()) / "journal_token";
  std::ofstream(token) << "journal-token-0123456789\n";
  const std::uint16_t port = test::free_port();
  auto server = start_server(port, dir, token, "journal_server1.log");
  ASSERT_EQ(viewer_sees(port).first, 0u) << server->output();
  const std::string connect = "--connect 127.0.0.1:" + std::to_string(port) + " --token-file " +
                              token.string() + " --json ";
  for (const char* e : kEdits) {
    const test::CliResult r = test::run_cli(IRRADCAST_EDIT_EXE, connect + "'" + e + "'");
    ASSERT_EQ(r.status, 0) << r.output << server->output();
  }
  const auto [revision, hash] = viewer_sees(port);
  ASSERT_EQ(revision, 4u);

  server->signal(SIGKILL);
  ASSERT_TRUE(server->wait_for(5s));
  server = start_server(port, dir, token, "journal_server2.log");
  EXPECT_EQ(viewer_sees(port), std::make_pair(std::uint64_t{4}, hash)) << server->output();
  EXPECT_NE(server->output().find("replayed 4 edits"), std::string::npos) << server->output();

  server->signal(SIGINT);
  ASSERT_TRUE(server->wait_for(10s));
  server = start_server(port, dir, token, "journal_server3.log");
  EXPECT_EQ(viewer_sees(port), std::make_pair(std::uint64_t{4}, hash)) << server->output();
  const test::CliResult r = test::run_cli(
      IRRADCAST_EDIT_EXE, connect + "'{\"op\": \"show\", \"node\": \"short_block\"}'");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_NE(r.output.find("revision 5 applied"), std::string::npos) << r.output;
  server->signal(SIGINT);
  server->wait_for(10s);
}

}  // namespace
}  // namespace irradcast::test_edit_journal
