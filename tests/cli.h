// Runs one of the command-line tools as a user would, capturing what it prints.
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace irradcast::test {

struct CliResult {
  int status = -1;     // exit status (-1: did not exit normally)
  std::string output;  // stdout and stderr together
};

inline CliResult run_cli(const std::string& exe, const std::string& args) {
  const std::string cmd = exe + " " + args + " 2>&1";
  CliResult r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf{};
  while (std::fgets(buf.data(), buf.size(), p)) r.output += buf.data();
  const int status = pclose(p);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace irradcast::test
