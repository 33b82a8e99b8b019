// The engine parameters' one list (engine_params.inc): every parameter reaches the command line,
// the bake report's JSON, validate() and the tile epoch, and a change of any of them, the edit
// parameters included, gives the published tiles another epoch.
#include <gtest/gtest.h>

#include "irradcast/common/cli.h"

#include <algorithm>
#include <initializer_list>
#include <iterator>
#include <limits>
#include <string>
#include <type_traits>
#include <vector>

#include "engine_options.h"
#include "irradcast/common/builtin.h"
#include "irradcast/common/error.h"
#include "irradcast/common/log.h"
#include "irradcast/common/progress.h"
#include "irradcast/engine/engine_params.h"
#include "irradcast/engine/pass_data.h"
#include "irradcast/service/engine_host.h"
#include "params_json.h"

namespace irradcast::test_engine_params {

namespace {

constexpr std::size_t kCount = std::size(kEngineParamSpecs);

// EngineParams' number of fields, counted by brace-initialising it with ever more values: no
// member can be declared outside engine_params.inc without this count telling.
struct AnyValue {
  template <class T>
  operator T() const;
};
template <class T, class... Values>
constexpr std::size_t field_count() {
  if constexpr (requires { T{Values{}..., AnyValue{}}; })
    return field_count<T, Values..., AnyValue>();
  else
    return sizeof...(Values);
}
static_assert(field_count<EngineParams>() == kCount,
              "every EngineParams member must be declared in engine_params.inc");

// Gives `v` another valid value and returns it as the command line spells it ("" for a flag).
template <class T>
std::string change(const ParamSpec& s, T& v) {
  if constexpr (std::is_same_v<T, bool>) {
    v = !v;
    return "";
  } else if constexpr (std::is_enum_v<T>) {
    v = static_cast<T>((static_cast<std::size_t>(v) + 1) % choice_names(v).size());
    return param_text(v);
  } else if constexpr (std::is_same_v<T, Length>) {
    v = Length::in_metres(s.kind == ParamKind::Distance ? 2.5f : 0.5f);
    return param_text(v);
  } else if constexpr (std::is_same_v<T, float>) {
    v = s.kind == ParamKind::Distance ? std::numeric_limits<float>::infinity() : v * 0.5f;
    return param_text(v);
  } else if constexpr (std::is_same_v<T, std::uint64_t>) {
    v = (std::uint64_t{1} << 60) + 1;  // not exact as a double
    return param_text(v);
  } else {
    v = v + 1;
    return param_text(v);
  }
}

// The defaults with parameter `i` changed; `text` gets the new value's command-line text.
EngineParams with_changed(std::size_t i, std::string* text) {
  EngineParams p;
  std::size_t k = 0;
  for_each_param(p, [&](const ParamSpec& s, auto& v) {
    if (k++ == i) *text = change(s, v);
  });
  return p;
}

// What the command line makes of `args` (after the program name).
EngineParams parse(std::vector<std::string> args) {
  tools::EngineOptions options;
  CLI::App app;
  options.add_to(app);
  std::reverse(args.begin(), args.end());  // CLI11 takes them last first
  app.parse(args);
  return options.params();
}

// Each of `texts` given to --cell-size is refused with an error that names cell_size.
void expect_cell_size_refused(std::initializer_list<const char*> texts) {
  for (const char* bad : texts) {
    SCOPED_TRACE(bad);
    try {
      parse({"--cell-size", bad});
      ADD_FAILURE() << "accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("cell_size"), std::string::npos) << e.what();
    }
  }
}

TEST(EngineParams, DenoiseIsOffByDefaultAndSetByItsFlag) {
  EXPECT_FALSE(EngineParams{}.denoise);
  EXPECT_FALSE(parse({}).denoise);
  EXPECT_TRUE(parse({"--denoise"}).denoise);
}

std::string first_flag(const ParamSpec& s) {
  const std::string flags = s.flags;
  return flags.substr(0, flags.find(','));
}

}  // namespace

TEST(EngineParams, DefaultsAreValidAndTheListNamesEachMemberOnce) {
  EXPECT_NO_THROW(EngineParams{}.validate());
  EXPECT_EQ(parse({}), EngineParams{});
  for (std::size_t i = 0; i < kCount; ++i)
    for (std::size_t j = i + 1; j < kCount; ++j) {
      EXPECT_STRNE(kEngineParamSpecs[i].name, kEngineParamSpecs[j].name);
      EXPECT_NE(first_flag(kEngineParamSpecs[i]), first_flag(kEngineParamSpecs[j]));
    }
}

// The next parameter added to engine_params.inc cannot be forgotten by the command line, the
// report or the tile epoch: each of them sees a change of every one.
TEST(EngineParams, EveryParameterReachesTheCommandLineTheReportAndTheEpochKey) {
  const EngineParams defaults;
  const nlohmann::json default_json = tools::params_json(defaults);
  EXPECT_EQ(default_json.size(), kCount);
  const std::string default_key = engine_params_key(defaults);
  for (std::size_t i = 0; i < kCount; ++i) {
    const ParamSpec& s = kEngineParamSpecs[i];
    SCOPED_TRACE(s.name);
    std::string text;
    const EngineParams changed = with_changed(i, &text);
    ASSERT_NE(changed, defaults);
    EXPECT_NO_THROW(changed.validate());
    // The command line: the flag sets exactly this parameter, and --help shows its text.
    std::vector<std::string> args = {first_flag(s)};
    if (!text.empty()) args.push_back(text);
    EXPECT_EQ(parse(args), changed) << first_flag(s) << " " << text;
    tools::EngineOptions options;
    CLI::App app;
    options.add_to(app);
    ASSERT_NE(app.get_option_no_throw(first_flag(s)), nullptr);
    EXPECT_EQ(app.get_option(first_flag(s))->get_description(), s.help);
    // The report: this key and no other changes.
    const nlohmann::json j = tools::params_json(changed);
    ASSERT_EQ(j.size(), kCount);
    for (const auto& [key, value] : j.items())
      if (key == s.name)
        EXPECT_NE(value, default_json.at(key));
      else
        EXPECT_EQ(value, default_json.at(key)) << key;
    // The tile epoch's key.
    EXPECT_NE(engine_params_key(changed), default_key);
  }
}

TEST(EngineParams, ValidateRefusesEveryParameterOutsideItsRangeByName) {
  for (std::size_t i = 0; i < kCount; ++i) {
    const ParamSpec& s = kEngineParamSpecs[i];
    if (s.kind == ParamKind::Choice || s.kind == ParamKind::Off || s.kind == ParamKind::On ||
        s.kind == ParamKind::Seed)
      continue;
    SCOPED_TRACE(s.name);
    // Just below the range, and just above it where it has an end.
    std::vector<double> bad = {s.kind == ParamKind::Positive ? s.lo : s.lo - 1};
    if (s.hi != kNoLimit) bad.push_back(s.hi + 1);
    for (double value : bad) {
      EngineParams p;
      std::size_t k = 0;
      for_each_param(p, [&](const ParamSpec&, auto& v) {
        using T = std::remove_reference_t<decltype(v)>;
        if constexpr (std::is_arithmetic_v<T>)
          if (k == i) v = static_cast<T>(value);
        if constexpr (std::is_same_v<T, Length>)
          if (k == i) v = Length(static_cast<float>(value));
        ++k;
      });
      try {
        p.validate();
        ADD_FAILURE() << value << " accepted";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(s.name), std::string::npos) << e.what();
      }
    }
  }
  // What a choice's text cannot name is refused with the parameter's name.
  EXPECT_THROW(parse({"--dispatch", "triangle"}), Error);
  EXPECT_THROW(parse({"--tracing-range", "far"}), Error);
  EXPECT_THROW(parse({"--bounces", "17"}), CLI::ValidationError);  // shown in --help
}

TEST(EngineParams, EpochKeyHoldsEveryBitOfTheSeed) {
  EngineParams a, b;
  a.seed = std::uint64_t{1} << 60;
  b.seed = a.seed + 1;
  EXPECT_NE(engine_params_key(a), engine_params_key(b));
}

// The edit parameters change the lightmaps published after an edit, so a server restarted with
// another value must not let a client keep its tiles (they were left out of the epoch once).
TEST(EngineParams, EditParametersChangeTheTileEpoch) {
  Progress::set_enabled(false);
  log::set_level(log::Level::Warn);
  auto epoch = [](void (*change)(EngineParams&)) {
    EngineHostOptions o;
    o.atlas.texels_per_scene = 32.0f;
    o.backend.kind = BackendKind::Embree;
    o.engine_nice = 0;
    change(o.engine);
    return EngineHost(make_cornell_box(), "cornell", o).tile_epoch();
  };
  const std::uint64_t defaults = epoch([](EngineParams&) {});
  EXPECT_EQ(epoch([](EngineParams&) {}), defaults);
  EXPECT_NE(epoch([](EngineParams& p) { p.edit_blend = 2.0f; }), defaults);
  EXPECT_NE(epoch([](EngineParams& p) { p.edit_batch = 1.0f; }), defaults);
  EXPECT_NE(epoch([](EngineParams& p) { p.edit_keep = 0; }), defaults);
}

// Sizes in metres (issue 33): --cell-size and --tracing-range take a fraction of the scene
// ("0.25"), metres ("2m") or, for the range, inf; the text reads back as the same value; the
// report and the tile epoch tell a fraction from metres; a grid in metres has cubes of that edge
// whatever the scene's size, and refuses more than 256 of them along the scene.
TEST(EngineParams, LengthsTakeMetres) {
  const EngineParams m = parse({"--cell-size", "2m", "--tracing-range", "2.4m"});
  EXPECT_EQ(m.cell_size, Length::in_metres(2.0f));
  EXPECT_EQ(m.tracing_range, Length::in_metres(2.4f));
  EXPECT_FALSE(m.unbiased());
  EXPECT_EQ(param_text(m.cell_size), "2m");
  EXPECT_EQ(parse({"--cell-size", "0.125"}).cell_size, Length(0.125f));
  EXPECT_TRUE(parse({"--tracing-range", "inf"}).unbiased());
  EXPECT_EQ(parse({"--tracing-range", "0m"}).tracing_range, Length::in_metres(0.0f));
  EXPECT_EQ(tools::params_json(m).at("cell_size"), "2m");
  EXPECT_EQ(tools::params_json(EngineParams{}).at("cell_size"), "0.25:1m");
  EXPECT_EQ(tools::params_json(parse({"--cell-size", "0.125"})).at("cell_size"), 0.125f);
  EngineParams fraction;
  fraction.cell_size = 2.0f / 8.0f;
  EngineParams metres;
  metres.cell_size = Length::in_metres(0.25f);
  EXPECT_NE(engine_params_key(fraction), engine_params_key(metres));
  expect_cell_size_refused({"m", "2mm", "-1m", "0m", "infm", "nanm", "2 m", "2km", "", "inf"});
  EXPECT_THROW(parse({"--tracing-range", "-0.5m"}), Error);
  EXPECT_THROW(parse({"--tracing-range", "far"}), Error);

  // A 40 x 3 x 10 m floor: 2 m cubes, 20 x 2 x 5 of them; as a fraction, 4 cubes of 10 m.
  const Bounds floor{glm::vec3(0.0f), glm::vec3(40.0f, 3.0f, 10.0f)};
  const ProbeGrid g = ProbeGrid::cells_of(floor, m);
  EXPECT_EQ(g.cell, 2.0f);
  EXPECT_EQ(g.dims, glm::ivec3(20, 2, 5));
  EngineParams fractions;
  fractions.cell_size = 0.25f;
  const ProbeGrid f = ProbeGrid::cells_of(floor, fractions);
  EXPECT_EQ(f.cell, 10.0f);
  EXPECT_EQ(f.dims, glm::ivec3(4, 1, 1));
  EngineParams huge;
  huge.cell_size = Length::in_metres(1e38f);  // one cell over the floor, its probe inside it
  const ProbeGrid h = ProbeGrid::cells_of(floor, huge);
  EXPECT_EQ(h.dims, glm::ivec3(1));
  EXPECT_EQ(h.cell, 40.0f);
  EXPECT_EQ(h.position[0], glm::vec3(20.0f));
  EngineParams tiny;
  tiny.cell_size = Length::in_metres(0.1f);  // 400 cells along 40 m
  try {
    ProbeGrid::cells_of(floor, tiny);
    ADD_FAILURE() << "400 cells accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("at most 256"), std::string::npos) << e.what();
  }
}

// The defaults (issue 33 part 2): fractions capped in metres, "0.25:1m" and "0.3:1.2m". A scene
// up to 4 m across keeps seed 001's fractions exactly; beyond, cells of 1 m and rays of 1.2 m;
// a scene too large for 1 m cubes gets cubes grown just enough to keep 256 along its largest
// extent and ProbeGrid::kMaxCappedCells in all, where an explicit size in metres is refused.
TEST(EngineParams, DefaultsAreFractionsCappedInMetres) {
  const EngineParams d;
  EXPECT_EQ(d.cell_size, Length::capped(0.25f, 1.0f));
  EXPECT_EQ(d.tracing_range, Length::capped(0.3f, 1.2f));
  EXPECT_EQ(param_text(d.cell_size), "0.25:1m");
  EXPECT_EQ(param_text(d.tracing_range), "0.3:1.2m");
  const EngineParams p = parse({"--cell-size", "0.5:2.5m", "--tracing-range", "0.1:0m"});
  EXPECT_EQ(p.cell_size, Length::capped(0.5f, 2.5f));
  EXPECT_EQ(p.tracing_range, Length::capped(0.1f, 0.0f));
  EXPECT_FALSE(p.unbiased());
  EXPECT_EQ(parse({"--cell-size", param_text(d.cell_size)}).cell_size, d.cell_size);
  EXPECT_EQ(d.tracing_range.resolve(2.0f), 0.3f * 2.0f);  // the fraction below the cap
  EXPECT_EQ(d.tracing_range.resolve(40.0f), 1.2f);        // the cap
  EXPECT_EQ(p.tracing_range.resolve(40.0f), 0.0f);
  EXPECT_NE(engine_params_key(d), engine_params_key(parse({"--cell-size", "0.25"})));
  expect_cell_size_refused({"0.25:", "0.25:1", ":1m", "0.25:-1m", "0.25:0m", "2:1m", "0:1m",
                            "inf:1m", "0.25:infm", "0.25:1m:2m", "0.25 :1m", "1m:0.25"});
  EXPECT_THROW(parse({"--tracing-range", "inf:1m"}), Error);
  EXPECT_THROW(parse({"--tracing-range", "0.3:-1m"}), Error);
  // Built in code rather than parsed: a cap that is not a number, negative or (for the cell)
  // zero, a cap on metres and an infinite fraction with a cap are refused too.
  EXPECT_NO_THROW(d.validate());
  const float inf = std::numeric_limits<float>::infinity(),
              nan = std::numeric_limits<float>::quiet_NaN();
  Length capped_metres = Length::in_metres(2.0f);
  capped_metres.cap = 1.0f;
  for (const Length bad :
       {Length::capped(0.25f, nan), Length::capped(0.25f, -inf), Length::capped(0.25f, 0.0f),
        Length::capped(0.25f, -1.0f), capped_metres}) {
    EngineParams q;
    q.cell_size = bad;
    EXPECT_THROW(q.validate(), Error) << param_text(bad);
  }
  for (const Length bad :
       {Length::capped(inf, 1.0f), Length::capped(0.3f, nan), Length::capped(0.3f, -1.0f)}) {
    EngineParams q;
    q.tracing_range = bad;
    EXPECT_THROW(q.validate(), Error) << param_text(bad);
  }

  // A 2 x 2 x 2 m box: the cap does not bind, the grid is the fraction's, bit for bit.
  EngineParams fractions;
  fractions.cell_size = 0.25f;
  const Bounds box{glm::vec3(0.0f), glm::vec3(2.0f)};
  const ProbeGrid small = ProbeGrid::cells_of(box, d), seed = ProbeGrid::cells_of(box, fractions);
  EXPECT_EQ(small.cell, seed.cell);
  EXPECT_EQ(small.dims, glm::ivec3(4));
  EXPECT_EQ(small.position, seed.position);
  // A 40 x 3 x 10 m floor: 1 m cubes, 40 x 3 x 10 of them.
  const Bounds floor{glm::vec3(0.0f), glm::vec3(40.0f, 3.0f, 10.0f)};
  const ProbeGrid g = ProbeGrid::cells_of(floor, d);
  EXPECT_EQ(g.cell, 1.0f);
  EXPECT_EQ(g.dims, glm::ivec3(40, 3, 10));
  // A 1 km floor, 3 m high: 256 cubes along it, at most kMaxCappedCells in all; a 1 km cube the
  // same. Explicit 1 m cubes are refused.
  for (const glm::vec3 size : {glm::vec3(1000.0f, 3.0f, 1000.0f), glm::vec3(1000.0f)}) {
    const ProbeGrid big = ProbeGrid::cells_of(Bounds{glm::vec3(0.0f), size}, d);
    EXPECT_LE(big.dims.x, 256);
    EXPECT_GE(big.cell, 1000.0f / 256.0f);
    EXPECT_LE(big.count(), ProbeGrid::kMaxCappedCells);
    EXPECT_GT(big.count(), ProbeGrid::kMaxCappedCells * 9 / 10);  // grown no more than needed
    EngineParams metres;
    metres.cell_size = Length::in_metres(1.0f);
    EXPECT_THROW(ProbeGrid::cells_of(Bounds{glm::vec3(0.0f), size}, metres), Error);
  }
}

}  // namespace irradcast::test_engine_params
