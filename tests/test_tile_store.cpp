#include <gtest/gtest.h>

#include "irradcast/common/error.h"
#include "irradcast/service/send_queue.h"
#include "irradcast/service/tile_store.h"

namespace irradcast::test_tile_store {

namespace {

Lightmap ramp(int w, int h, float scale) {
  Lightmap m(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      m.texels[static_cast<std::size_t>(y) * w + x] =
          scale * glm::vec3(1.0f + x, 2.0f + y, 0.5f + 0.1f * (x + y));
  return m;
}

}  // namespace

TEST(TileStore, CutsLightmapsIntoTilesWithEdgeTiles) {
  TileStoreOptions o;
  o.tile_size = 16;
  TileStore store({{40, 16}, {8, 8}}, o);
  EXPECT_EQ(store.tiles_x(0), 3);
  EXPECT_EQ(store.tiles_y(0), 1);
  EXPECT_EQ(store.tile_count(), 4u);
  EXPECT_EQ(store.tile(2).rect.w, 8);  // 40 = 16 + 16 + 8
  EXPECT_EQ(store.index(1, 0, 0), 3);
  EXPECT_EQ(store.index(1, 1, 0), -1);
  EXPECT_EQ(store.index(2, 0, 0), -1);
  EXPECT_EQ(store.version(0), 0u);
  EXPECT_EQ(store.snapshot(0, wire::TILE_RGB9E5_ZSTD).payload, nullptr);
}

TEST(TileStore, OnlyTilesThatChangedBeyondTheThresholdGetNewVersions) {
  TileStoreOptions o;
  o.tile_size = 8;
  o.change_threshold = 0.01f;
  TileStore store({{16, 8}}, o);
  Lightmap a = ramp(16, 8, 1.0f);
  auto first = store.publish({a}, 100);
  EXPECT_EQ(first.size(), 2u) << "the first publish versions every tile";
  // A change of 0.1% in the left tile only: below the threshold, no new version.
  Lightmap b = a;
  b.texels[3] *= 1.001f;
  EXPECT_TRUE(store.publish({b}, 200).empty());
  // 5% over the whole right tile: a new version for that tile alone, with its time stamp.
  for (int y = 0; y < 8; ++y)
    for (int x = 8; x < 16; ++x) b.texels[y * 16 + x] *= 1.05f;
  auto changed = store.publish({b}, 300);
  ASSERT_EQ(changed.size(), 1u);
  EXPECT_EQ(changed[0], 1u);
  EXPECT_EQ(store.version(0), 1u);
  EXPECT_EQ(store.version(1), 2u);
  auto snap = store.snapshot(1, wire::TILE_RGB9E5_ZSTD);
  EXPECT_EQ(snap.time_us, 300u);
  // The payload decodes to the published values within RGB9E5's error.
  Lightmap decoded(16, 8);
  wire::decode_tile(*snap.payload, wire::TILE_RGB9E5_ZSTD, store.tile(1).rect, decoded);
  const Lightmap published = store.published()[0];
  for (int y = 0; y < 8; ++y)
    for (int x = 8; x < 16; ++x) {
      const glm::vec3 v = published.texels[y * 16 + x], d = decoded.texels[y * 16 + x];
      const float m = std::max(v.x, std::max(v.y, v.z));
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(d[c], v[c], 2.5e-3f * m);
    }
  // The criterion is the tile's RMS change against its mean level: a single texel changing by
  // 5% in 64 does not count (0.6% RMS), one changing by 50% does.
  Lightmap c = b;
  c.texels[2] *= 1.05f;
  EXPECT_TRUE(store.publish({c}, 400).empty());
  c.texels[2] *= 1.5f;
  EXPECT_EQ(store.publish({c}, 500), std::vector<std::uint32_t>{0});
  // Half floats are encoded on request from the same values.
  auto half = store.snapshot(1, wire::TILE_HALF_ZSTD);
  ASSERT_NE(half.payload, nullptr);
  EXPECT_EQ(half.version, 2u);
  EXPECT_GT(store.bytes_per_texel(), 0.0);
  EXPECT_LT(store.bytes_per_texel(), 4.5);
}

TEST(TileStore, RejectsMismatchedInput) {
  TileStore store({{16, 8}});
  EXPECT_THROW(store.publish({}, 0), Error);
  EXPECT_THROW(store.publish({Lightmap(8, 8)}, 0), Error);
  TileStoreOptions bad;
  bad.tile_size = 0;
  EXPECT_THROW(TileStore({{16, 8}}, bad), Error);
}

TEST(SendQueue, HoldsEachTileOnceAndCountsCoalescedVersions) {
  SendQueue q(10);
  EXPECT_TRUE(q.push(3));
  EXPECT_TRUE(q.push(7));
  EXPECT_FALSE(q.push(3));   // a newer version of a waiting tile: no second entry
  EXPECT_FALSE(q.push(42));  // out of range: ignored
  EXPECT_EQ(q.size(), 2u);
  EXPECT_EQ(q.coalesced(), 1u);
  std::uint32_t t = 0;
  ASSERT_TRUE(q.pop(t));
  EXPECT_EQ(t, 3u);
  EXPECT_TRUE(q.push(3));  // sent, so it may wait again
  ASSERT_TRUE(q.pop(t));
  EXPECT_EQ(t, 7u);
  ASSERT_TRUE(q.pop(t));
  EXPECT_EQ(t, 3u);
  EXPECT_FALSE(q.pop(t));
  // However often tiles change, the queue never holds more than one entry per tile.
  for (int round = 0; round < 100; ++round)
    for (std::uint32_t i = 0; i < 10; ++i) q.push(i);
  EXPECT_EQ(q.size(), 10u);
}

// With the engine's noise: a change of the size of the noise waits for the refresh ratio
// (R^(1+h) more samples, h spread over the tiles), a change well beyond it goes out at once.
TEST(TileStore, ChangesWithinTheEnginesNoiseWaitForTheRefreshRatio) {
  TileStoreOptions o;
  o.tile_size = 8;
  o.change_threshold = 0.01f;
  o.refresh_ratio = 2.0f;
  o.significance = 2.0f;
  const int tiles_x = 16, w = 8 * tiles_x, h = 8;
  TileStore store({{w, h}}, o);
  Lightmap level(w, h);
  for (glm::vec3& t : level.texels) t = glm::vec3(1.0f);
  // Standard error of each texel's mean: 5% of the level.
  Lightmap se(w, h);
  for (glm::vec3& t : se.texels) t = glm::vec3(0.05f);
  const std::vector<Lightmap> ses{se};
  TileStore::Noise noise{1, &ses};
  ASSERT_EQ(store.publish({level}, 1, &noise).size(), static_cast<std::size_t>(tiles_x));

  // A noise-sized change: 4% RMS (above the 1% threshold) where a change of se * sqrt(3 - 1) =
  // 7% RMS is expected from noise alone at 3x the samples: not significant, so a tile waits
  // unless 3x reaches its refresh ratio.
  Lightmap noisy = level;
  for (std::size_t i = 0; i < noisy.texels.size(); ++i)
    noisy.texels[i] = glm::vec3(i % 2 ? 1.04f : 0.96f);
  noise.samples = 3;  // 3 / 1 = 3x: tiles with 2^(1+h) <= 3 refresh, the others wait
  const std::size_t refreshed = store.publish({noisy}, 2, &noise).size();
  EXPECT_GT(refreshed, 0u);
  EXPECT_LT(refreshed, static_cast<std::size_t>(tiles_x)) << "the refreshes are spread";
  // The others all refresh by 4x the samples.
  noise.samples = 4;
  EXPECT_EQ(refreshed + store.publish({noisy}, 3, &noise).size(),
            static_cast<std::size_t>(tiles_x));

  // A real change (+50% in tile 5) at only 1.25x the samples: beyond the noise, out at once;
  // the other tiles, unchanged, stay.
  noise.samples = 5;
  Lightmap edited = noisy;
  for (int y = 0; y < h; ++y)
    for (int x = 40; x < 48; ++x) edited.texels[static_cast<std::size_t>(y) * w + x] *= 1.5f;
  const auto changed = store.publish({edited}, 4, &noise);
  ASSERT_EQ(changed.size(), 1u);
  EXPECT_EQ(changed[0], 5u);

  // Without noise information every change beyond the threshold gets a version, as before.
  Lightmap back = edited;
  for (std::size_t i = 0; i < back.texels.size(); ++i) back.texels[i] *= 1.02f;
  EXPECT_EQ(store.publish({back}, 5).size(), static_cast<std::size_t>(tiles_x));
}

// A fresh server's first update has no error estimate yet: its versions still record their
// samples, so that the second update refreshes only the tiles whose refresh ratio 2x reaches
// (or whose change is beyond the noise), not the whole image at once.
TEST(TileStore, TheFirstVersionsRecordTheirSamplesWithoutAnErrorEstimate) {
  TileStoreOptions o;
  o.tile_size = 8;
  o.refresh_ratio = 2.0f;
  const int tiles_x = 16, w = 8 * tiles_x, h = 8;
  TileStore store({{w, h}}, o);
  Lightmap level(w, h);
  for (glm::vec3& t : level.texels) t = glm::vec3(1.0f);
  const TileStore::Noise first{1, nullptr};
  ASSERT_EQ(store.publish({level}, 1, &first).size(), static_cast<std::size_t>(tiles_x));
  Lightmap se(w, h);
  for (glm::vec3& t : se.texels) t = glm::vec3(0.05f);
  const std::vector<Lightmap> ses{se};
  Lightmap noisy = level;
  for (std::size_t i = 0; i < noisy.texels.size(); ++i)
    noisy.texels[i] = glm::vec3(i % 2 ? 1.04f : 0.96f);
  const TileStore::Noise second{2, &ses};
  const std::size_t refreshed = store.publish({noisy}, 2, &second).size();
  EXPECT_LT(refreshed, static_cast<std::size_t>(tiles_x) / 4) << "a burst of the whole image";
  // Without the first update's sample count (no noise at all), every tile refreshed.
  TileStore unaware({{w, h}}, o);
  unaware.publish({level}, 1);
  EXPECT_EQ(unaware.publish({noisy}, 2, &second).size(), static_cast<std::size_t>(tiles_x));
}

TEST(TileStore, RejectsARefreshRatioBelowOne) {
  TileStoreOptions o;
  o.refresh_ratio = 0.5f;
  EXPECT_THROW(TileStore({{8, 8}}, o), Error);
}

}  // namespace irradcast::test_tile_store
