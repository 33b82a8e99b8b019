// CLI11, as every tool, bench and test of the command line includes it: its code compiled without
// optimisation. CLI11 2.1 is header-only (no precompiled mode), and each file that includes it
// compiled its whole parser, help formatter and validators again at the build's level, for a
// command line parsed once per run. Measured on this project's Debian 12 machine, a file with
// an App of four options: 19.2 s at GCC -O3, 9.2 s with this header; clang -O2 with ASan + UBSan
// 27.1 s, 18.5 s.
//
// The standard headers CLI11 uses are included first, outside the unoptimised region, so that
// std::vector, std::string and the rest keep the build's level in the including file's own code.
#pragma once

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <iostream>
#include <iterator>
#include <limits>
#include <locale>
#include <map>
#include <memory>
#include <numeric>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include <sys/stat.h>
#include <sys/types.h>

#if defined(__clang__)
#pragma clang optimize off
#elif defined(__GNUC__)
#pragma GCC push_options
#pragma GCC optimize("O0")
#endif

#include <CLI/CLI.hpp>  // IWYU pragma: export

#if defined(__clang__)
#pragma clang optimize on
#elif defined(__GNUC__)
#pragma GCC pop_options
#endif
