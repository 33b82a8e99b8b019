// Runs an io_context on the calling thread until it stops; a handler that throws is logged
// ("<component>: <what> failed: ...") and the loop goes on serving the other handlers.
#pragma once

// A standard header before asio: asio's config decides between aligned_alloc and operator new
// from libstdc++'s _GLIBCXX_HAVE_ALIGNED_ALLOC, so every file must see it defined alike (else
// one file allocates handler memory with aligned_alloc and another frees it with delete).
#include <cstddef>

#include <asio.hpp>

#include <exception>
#include <string>

#include "irradcast/common/log.h"

namespace irradcast {

inline void run_io(asio::io_context& io, const char* component, const std::string& what) {
  for (;;) {
    try {
      io.run();
      break;
    } catch (const std::exception& e) {
      log::error(component, what + " failed: " + e.what());
    }
  }
}

}  // namespace irradcast
