// Structured, leveled log lines on stderr:  2026-11-22T08:30:01.123Z INFO  bake  message
#pragma once

#include <string>
#include <string_view>

namespace irradcast::log {

enum class Level { Debug = 0, Info = 1, Warn = 2, Error = 3, Off = 4 };

void set_level(Level level);
Level level();
// Parses "debug|info|warn|error|off"; throws irradcast::Error otherwise.
Level parse_level(std::string_view name);

// Writes one line. Control characters in the message are escaped (a newline becomes "\\n"), so
// no text, whoever wrote it, can start a line of its own.
void write(Level level, std::string_view component, std::string_view message);

// Text from outside (a client's name, an Error message, a node name) for a log line, quoted:
// '...' with control characters, quotes and bytes above 0x7e escaped as \xNN and at most
// max_bytes of the text shown, then "...(N bytes)".
std::string quote(std::string_view text, std::size_t max_bytes = 120);

inline void debug(std::string_view c, std::string_view m) {
  write(Level::Debug, c, m);
}
inline void info(std::string_view c, std::string_view m) {
  write(Level::Info, c, m);
}
inline void warn(std::string_view c, std::string_view m) {
  write(Level::Warn, c, m);
}
inline void error(std::string_view c, std::string_view m) {
  write(Level::Error, c, m);
}

}  // namespace irradcast::log
