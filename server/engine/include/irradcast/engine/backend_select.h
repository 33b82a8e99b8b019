// Which TraceBackend runs the engine's passes, and where the reference path tracer runs
// (--backend auto|vulkan|embree).
//   vulkan: the Vulkan compute backend, or a clear error when it cannot start.
//   embree: the CPU backend.
//   auto:   Vulkan on a GPU when one opens; otherwise Embree, with the reason logged. A Vulkan
//           device that is itself a CPU implementation (Mesa's lavapipe) is not picked by auto:
//           Embree on the same cores is faster (docs/BENCHMARKS.md); ask for it by name.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "irradcast/common/lights.h"
#include "irradcast/common/ray_scene.h"
#include "irradcast/engine/path_tracer.h"
#include "irradcast/engine/reference.h"
#include "irradcast/engine/trace_backend.h"
#include "irradcast/engine/vulkan_device.h"

namespace irradcast {

enum class BackendKind { Auto, Vulkan, Embree };

// "auto" | "vulkan" | "embree"; throws irradcast::Error naming the bad value.
BackendKind parse_backend(const std::string& name);

// The device --backend auto runs on: the best Vulkan GPU with compute (discrete, integrated,
// virtual, other), as an index into `devices`; -1 when there is none. CPU implementations
// (lavapipe) are never picked.
int auto_vulkan_device(const std::vector<VulkanDeviceInfo>& devices);

struct BackendOptions {
  BackendKind kind = BackendKind::Auto;
  int vulkan_device = -1;          // --vulkan-device: index from --list-devices; -1 = best
  bool vulkan_validation = false;  // --vulkan-validation: Khronos validation layer on
};

struct BackendChoice {
  std::unique_ptr<TraceBackend> backend;
  std::string reason;  // one line: what runs and why ("vulkan on ...", "embree: ...")
};

// Makes the backend (and logs the choice). `rays` and `lights` must outlive it. Throws
// irradcast::Error when kind is Vulkan and no Vulkan device can be opened.
BackendChoice make_backend(const BackendOptions& options, const World& world, const RayScene& rays,
                           const LightSampler& lights);

// The reference path tracer on the device make_backend would pick: reference.comp on the
// Vulkan backend, or PathTracer on the CPU with `tracer`'s bounces and seed (logs the choice
// like make_backend); always the CPU's with tracer.camera_only (dynamic objects). `world`,
// `rays` and `lights` must outlive it.
std::unique_ptr<ReferenceRenderer> make_reference(const BackendOptions& options, const World& world,
                                                  const RayScene& rays, const LightSampler& lights,
                                                  const PathTracerOptions& tracer);

}  // namespace irradcast
