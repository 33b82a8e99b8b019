#include "irradcast/common/log.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <mutex>
#include <string>

#include "irradcast/common/error.h"

namespace irradcast::log {
namespace {
std::atomic<int> g_level{static_cast<int>(Level::Info)};
std::mutex g_mutex;

const char* name(Level l) {
  switch (l) {
    case Level::Debug:
      return "DEBUG";
    case Level::Info:
      return "INFO ";
    case Level::Warn:
      return "WARN ";
    case Level::Error:
      return "ERROR";
    case Level::Off:
      break;
  }
  return "?";
}
}  // namespace

void set_level(Level level) {
  g_level = static_cast<int>(level);
}
Level level() {
  return static_cast<Level>(g_level.load());
}

Level parse_level(std::string_view s) {
  if (s == "debug") return Level::Debug;
  if (s == "info") return Level::Info;
  if (s == "warn") return Level::Warn;
  if (s == "error") return Level::Error;
  if (s == "off") return Level::Off;
  throw Error("unknown log level '" + std::string(s) +
              "' (expected debug, info, warn, error, off)");
}

namespace {

bool is_control(unsigned char c) {
  return c < 0x20 || c == 0x7f;
}

void escape_into(std::string& out, unsigned char c) {
  static const char* hex = "0123456789abcdef";
  switch (c) {
    case '\n':
      out += "\\n";
      return;
    case '\r':
      out += "\\r";
      return;
    case '\t':
      out += "\\t";
      return;
    default:
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
  }
}

}  // namespace

std::string quote(std::string_view text, std::size_t max_bytes) {
  std::string out = "'";
  const std::size_t shown = std::min(text.size(), max_bytes);
  for (std::size_t i = 0; i < shown; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (is_control(c) || c > 0x7e || c == '\'' || c == '\\')
      escape_into(out, c);
    else
      out += static_cast<char>(c);
  }
  out += "'";
  if (shown < text.size()) out += "...(" + std::to_string(text.size()) + " bytes)";
  return out;
}

void write(Level lvl, std::string_view component, std::string_view message) {
  if (static_cast<int>(lvl) < g_level.load() || lvl == Level::Off) return;
  std::string escaped;
  if (std::any_of(message.begin(), message.end(),
                  [](char c) { return is_control(static_cast<unsigned char>(c)); })) {
    for (char c : message) {
      if (is_control(static_cast<unsigned char>(c)))
        escape_into(escaped, static_cast<unsigned char>(c));
      else
        escaped += c;
    }
    message = escaped;
  }
  using namespace std::chrono;
  auto now = system_clock::now();
  std::time_t t = system_clock::to_time_t(now);
  int ms = static_cast<int>(duration_cast<milliseconds>(now.time_since_epoch()).count() % 1000);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%S", &tm);
  std::lock_guard lock(g_mutex);
  std::fprintf(stderr, "%s.%03dZ %s %-7.*s %.*s\n", stamp, ms, name(lvl),
               static_cast<int>(component.size()), component.data(),
               static_cast<int>(message.size()), message.data());
}

}  // namespace irradcast::log
