// LoadOptions's checks (load_generator.h).
#include "irradcast/client/load_generator.h"
#include "irradcast/common/error.h"

namespace irradcast {

void LoadOptions::validate() const {
  if (users < 1) throw Error("--users must be at least 1");
  if (!(duration_s > 0.0)) throw Error("--duration must be positive");
  if (render && (width < 1 || height < 1 || width > 8192 || height > 8192))
    throw Error("--width and --height must be in 1..8192");
  if (fps < 0.0 || camera_hz < 0.0 || ramp_s < 0.0)
    throw Error("--fps, --camera-hz and --ramp must not be negative");
  if (threads < 0) throw Error("--threads must not be negative");
  if (ramp_s >= duration_s) throw Error("--ramp must be shorter than --duration");
  backoff.validate();
}

}  // namespace irradcast
