// Where the tests find the sample data (the glTF samples): the directory in the environment
// variable IRRADCAST_TESTDATA, else <source>/../shared/testdata (IRRADCAST_TESTDATA_DEFAULT,
// from tests/CMakeLists.txt). A test that reads it starts with IRRADCAST_NEED_TESTDATA(): where
// the directory is absent the test skips, naming it, so a bare clone passes; with
// IRRADCAST_TESTDATA_REQUIRED=1 (CI, .ci/run) it fails instead.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace irradcast::test {

inline std::string testdata_dir() {
  const char* dir = std::getenv("IRRADCAST_TESTDATA");
  return dir != nullptr && *dir != '\0' ? dir : IRRADCAST_TESTDATA_DEFAULT;
}

// A path under the sample data directory.
inline std::string testdata(const std::string& relative) {
  return testdata_dir() + "/" + relative;
}

inline bool testdata_required() {
  const char* required = std::getenv("IRRADCAST_TESTDATA_REQUIRED");
  return required != nullptr && std::string(required) == "1";
}

}  // namespace irradcast::test

#define IRRADCAST_NEED_TESTDATA()                                                              \
  do {                                                                                         \
    const std::string testdata_dir_ = ::irradcast::test::testdata_dir();                       \
    if (!std::filesystem::is_directory(testdata_dir_)) {                                       \
      if (::irradcast::test::testdata_required())                                              \
        FAIL() << "no sample data at " << testdata_dir_ << " (IRRADCAST_TESTDATA_REQUIRED=1)"; \
      GTEST_SKIP() << "no sample data at " << testdata_dir_                                    \
                   << " (set IRRADCAST_TESTDATA to the directory holding gltf-samples/)";      \
    }                                                                                          \
  } while (0)
