// Helpers for the tests that write glTF files: a scratch directory per test, base64 data URIs,
// and the POSITION accessor of the one-triangle models they start from.
#pragma once

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <string>
#include <system_error>
#include <utility>

#include <nlohmann/json.hpp>

namespace irradcast::test {

// A fresh temporary directory per test, dir_ = <tmp>/<prefix><test name>_<pid>, removed after.
class ScratchDirTest : public ::testing::Test {
 protected:
  explicit ScratchDirTest(std::string prefix) : prefix_(std::move(prefix)) {}
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           (prefix_ + std::string(info->name()) + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::filesystem::path dir_;

 private:
  std::string prefix_;
};

// `bytes` as a base64 data URI (application/octet-stream), as a glTF buffer may embed them.
inline std::string data_uri(const std::string& bytes) {
  static const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out = "data:application/octet-stream;base64,";
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    std::uint32_t v = static_cast<unsigned char>(bytes[i]) << 16;
    if (i + 1 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 1]) << 8;
    if (i + 2 < bytes.size()) v |= static_cast<unsigned char>(bytes[i + 2]);
    out += table[(v >> 18) & 63];
    out += table[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? table[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? table[v & 63] : '=';
  }
  return out;
}

// Accessor of the three float VEC3 positions (0,0,0) (1,0,0) (0,1,0) at the start of bufferView 0.
inline nlohmann::json triangle_positions_accessor() {
  return {{"bufferView", 0}, {"componentType", 5126}, {"count", 3},
          {"type", "VEC3"},  {"min", {0, 0, 0}},      {"max", {1, 1, 0}}};
}

}  // namespace irradcast::test
