// Error: the one exception type for bad input (files, arguments, frames).
// Its message is a complete, user-facing sentence naming the input and the problem.
#pragma once

#include <stdexcept>
#include <string>

namespace irradcast {

class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace irradcast
