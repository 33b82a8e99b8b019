// irradcast-bench-journal: what durability costs per edit (docs/BENCHMARKS.md, "Durable edits").
// An EngineHost on the Cornell box takes the same edits with and without a state folder, in
// alternating rounds in one run: the time of submit_edit (validation, and with the folder the
// journal's append and fsync before the edit is acknowledged), and the journal's bytes per edit
// and compaction time. The host is not started, so only the acknowledgement path is timed; the
// engine applies the edits between rounds (step()). The folder (--dir, default OUT/state) decides
// what an fsync costs: run it on the disk a server's --state-dir would use.
#include <nlohmann/json.hpp>
#include "irradcast/common/cli.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "bench_util.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/scene_edit.h"
#include "irradcast/service/engine_host.h"

namespace fs = std::filesystem;
using json = nlohmann::json;
using namespace irradcast;

namespace {

struct Options {
  std::string out = "out/bench-journal";
  std::string dir;
  int rounds = 6;
  int edits = 50;
};

// The i-th edit of a round: moves and albedo changes that cancel out over a round's pairs.
SceneEdit edit_of(int i) {
  const float s = (i % 2 == 0) ? 0.01f : -0.01f;
  if (i % 4 < 2)
    return parse_edit_json(R"({"op": "move", "node": "tall_block", "by": [)" + std::to_string(s) +
                           ", 0, 0]}");
  return parse_edit_json(R"({"op": "albedo", "material": "red", "color": [0.6, )" +
                         std::to_string(0.1f + s) + ", 0.05]}");
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<std::size_t>(p * static_cast<double>(v.size())))];
}

// Microseconds of each submit_edit of one round.
std::vector<double> round_of(EngineHost& host, int edits) {
  std::vector<double> us;
  for (int i = 0; i < edits; ++i) {
    const SceneEdit e = edit_of(i);
    const auto t0 = bench::Clock::now();
    host.submit_edit(e);
    us.push_back(1e6 * bench::seconds_since(t0));
  }
  host.step();  // the engine applies them (not timed)
  return us;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"irradcast-bench-journal: the cost of the durable edit journal per edit",
               "irradcast-bench-journal"};
  app.add_option("--out", o.out, "output folder (journal.json)");
  app.add_option("--dir", o.dir, "the state folder to measure (default OUT/state)");
  app.add_option("--rounds", o.rounds, "alternating rounds per side")->check(CLI::PositiveNumber);
  app.add_option("--edits", o.edits, "edits per round")->check(CLI::Range(2, 2000));
  CLI11_PARSE(app, argc, argv);
  return bench::run_guarded("irradcast-bench-journal: ", [&] {
    std::string json_path;
    auto threads = bench::start_run(1, o.out, json_path, "journal.json");
    const fs::path dir = o.dir.empty() ? fs::path(o.out) / "state" : fs::path(o.dir);
    fs::remove_all(dir);
    EngineHostOptions plain;
    plain.atlas.texels_per_scene = 32.0f;
    plain.max_updates = 1;
    EngineHostOptions durable = plain;
    durable.state_dir = dir.string();
    durable.journal_compact_after = 0;  // compaction timed on its own below
    EngineHost memory(make_cornell_box(), "cornell", plain);
    EngineHost journaled(make_cornell_box(), "cornell", durable);
    std::vector<double> mem_us, jrn_us;
    for (int r = 0; r < o.rounds; ++r) {
      for (double v : round_of(memory, o.edits)) mem_us.push_back(v);
      for (double v : round_of(journaled, o.edits)) jrn_us.push_back(v);
    }
    const double journal_bytes = static_cast<double>(fs::file_size(dir / EditJournal::kFileName));
    const int total = o.rounds * o.edits;
    // Compaction: a host whose journal compacts after every `edits` edits, one round.
    const fs::path cdir = dir.string() + "-compact";
    fs::remove_all(cdir);
    EngineHostOptions compacting = durable;
    compacting.state_dir = cdir.string();
    compacting.journal_compact_after = static_cast<std::uint32_t>(o.edits);
    EngineHost compact_host(make_cornell_box(), "cornell", compacting);
    const std::vector<double> with_compaction = round_of(compact_host, o.edits);
    const double compaction_us = with_compaction.back();  // the last edit of the round compacts
    json rows = json::array();
    auto row = [&](const char* side, const std::vector<double>& us) {
      json j{{"side", side},
             {"edits", us.size()},
             {"median_us", bench::median(us)},
             {"p99_us", percentile(us, 0.99)},
             {"max_us", *std::max_element(us.begin(), us.end())}};
      std::printf("%-10s %6zu edits  median %9.1f us  p99 %9.1f us  max %9.1f us\n", side,
                  us.size(), bench::median(us), percentile(us, 0.99),
                  *std::max_element(us.begin(), us.end()));
      rows.push_back(j);
    };
    std::printf("state folder: %s\n", dir.c_str());
    row("memory", mem_us);
    row("journal", jrn_us);
    const double ratio = bench::median(jrn_us) / std::max(bench::median(mem_us), 1e-9);
    std::printf(
        "journal / memory (median): %.1fx; %.0f bytes per edit in the journal; an edit "
        "that compacts: %.1f us\n",
        ratio, journal_bytes / total, compaction_us);
    json report{{"bench", "journal"},
                {"machine", bench::machine_json(1)},
                {"state_dir", dir.string()},
                {"rounds", o.rounds},
                {"edits_per_round", o.edits},
                {"sides", rows},
                {"journal_over_memory_median", ratio},
                {"journal_bytes_per_edit", journal_bytes / total},
                {"compacting_edit_us", compaction_us}};
    bench::write_json(json_path, report);
    return 0;
  });
}
