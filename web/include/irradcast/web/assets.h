// The viewer page's files, embedded in the binary at build time (web/CMakeLists.txt runs
// web/build.mjs, then web/tools/embed_assets.cpp turns its output folder into a table). The
// server serves only these names: no file system path is ever opened for a request.
#pragma once

#include <cstddef>
#include <string_view>

namespace irradcast::web {

struct Asset {
  std::string_view path;          // "/index.html", "/viewer.js", ...
  std::string_view content_type;  // "text/html; charset=utf-8", ...
  std::string_view body;
};

// The asset at `path` (a URL path without query: "/" is "/index.html"); nullptr when there is
// none.
const Asset* find_asset(std::string_view path);

// Every asset, for listings and tests.
const Asset* assets_begin();
const Asset* assets_end();

}  // namespace irradcast::web
