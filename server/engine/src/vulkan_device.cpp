#include "irradcast/engine/vulkan_device.h"

#include <vulkan/vulkan.h>

#include "irradcast/common/sanitizer.h"
#if IRRADCAST_ASAN
#include <sanitizer/lsan_interface.h>
// Mesa's lavapipe (Debian 12's mesa-vulkan-drivers 22.3.6-1+deb12u2) leaks 128 bytes each time
// it enumerates its devices, inside the driver, which the loader unloads before LeakSanitizer
// reports (so no suppression can name it; a plain C program that only enumerates leaks the
// same). Allocations in the scope of this are not reported; sanitizer builds only.
#define IRRADCAST_DRIVER_LEAKS_NOT_REPORTED __lsan::ScopedDisabler driver_leaks_not_reported
#else
#define IRRADCAST_DRIVER_LEAKS_NOT_REPORTED (void)0
#endif

#include <algorithm>
#include <cstring>
#include <mutex>

#include "irradcast/common/code_names.h"
#include "irradcast/common/error.h"
#include "vulkan_handles.h"

namespace irradcast {

namespace {

constexpr CodeName kResultNames[] = {
    {VK_SUCCESS, "VK_SUCCESS"},
    {VK_ERROR_OUT_OF_HOST_MEMORY, "VK_ERROR_OUT_OF_HOST_MEMORY"},
    {VK_ERROR_OUT_OF_DEVICE_MEMORY, "VK_ERROR_OUT_OF_DEVICE_MEMORY"},
    {VK_ERROR_INITIALIZATION_FAILED, "VK_ERROR_INITIALIZATION_FAILED"},
    {VK_ERROR_DEVICE_LOST, "VK_ERROR_DEVICE_LOST"},
    {VK_ERROR_LAYER_NOT_PRESENT, "VK_ERROR_LAYER_NOT_PRESENT"},
    {VK_ERROR_EXTENSION_NOT_PRESENT, "VK_ERROR_EXTENSION_NOT_PRESENT"},
    {VK_ERROR_FEATURE_NOT_PRESENT, "VK_ERROR_FEATURE_NOT_PRESENT"},
    {VK_ERROR_INCOMPATIBLE_DRIVER, "VK_ERROR_INCOMPATIBLE_DRIVER (no Vulkan driver)"},
    {VK_ERROR_TOO_MANY_OBJECTS, "VK_ERROR_TOO_MANY_OBJECTS"},
};

constexpr CodeName kDeviceTypeNames[] = {
    {VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU, "integrated GPU"},
    {VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU, "discrete GPU"},
    {VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU, "virtual GPU"},
    {VK_PHYSICAL_DEVICE_TYPE_CPU, "CPU"},
};

std::string result_name(VkResult r) {
  if (const char* name = code_name(r, kResultNames, nullptr)) return name;
  return "VkResult " + std::to_string(static_cast<int>(r));
}

void check(VkResult r, const char* what) {
  if (r != VK_SUCCESS) throw Error(std::string(what) + ": " + result_name(r));
}

std::string version_string(std::uint32_t v) {
  return std::to_string(VK_API_VERSION_MAJOR(v)) + "." + std::to_string(VK_API_VERSION_MINOR(v)) +
         "." + std::to_string(VK_API_VERSION_PATCH(v));
}

std::string type_name(VkPhysicalDeviceType t) {
  return code_name(t, kDeviceTypeNames, "other");
}

int type_rank(const std::string& type) {
  if (type == "discrete GPU") return 0;
  if (type == "integrated GPU") return 1;
  if (type == "virtual GPU") return 2;
  if (type == "CPU") return 3;
  return 4;
}

bool has_layer(const char* name) {
  std::uint32_t n = 0;
  vkEnumerateInstanceLayerProperties(&n, nullptr);
  std::vector<VkLayerProperties> layers(n);
  vkEnumerateInstanceLayerProperties(&n, layers.data());
  return std::any_of(layers.begin(), layers.end(), [&](const VkLayerProperties& l) {
    return std::strcmp(l.layerName, name) == 0;
  });
}

constexpr const char* kValidationLayer = "VK_LAYER_KHRONOS_validation";

// An instance, optionally with validation and a debug messenger feeding `sink`.
struct Instance {
  VkInstance handle = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;

  Instance(bool validation, PFN_vkDebugUtilsMessengerCallbackEXT callback, void* user) {
    VkApplicationInfo app{};
    app.sType = VK_STRUCTURE_TYPE_APPLICATION_INFO;
    app.pApplicationName = "irradcast";
    app.apiVersion = VK_API_VERSION_1_1;
    std::vector<const char*> layers, extensions;
    if (validation) {
      if (!has_layer(kValidationLayer))
        throw Error(std::string("the Vulkan validation layer ") + kValidationLayer +
                    " is not installed (Debian: vulkan-validationlayers)");
      layers.push_back(kValidationLayer);
      extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
    }
    VkInstanceCreateInfo info{};
    info.sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO;
    info.pApplicationInfo = &app;
    info.enabledLayerCount = static_cast<std::uint32_t>(layers.size());
    info.ppEnabledLayerNames = layers.data();
    info.enabledExtensionCount = static_cast<std::uint32_t>(extensions.size());
    info.ppEnabledExtensionNames = extensions.data();
    VkDebugUtilsMessengerCreateInfoEXT dbg{};
    if (validation) {
      dbg.sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT;
      dbg.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                            VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
      dbg.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                        VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                        VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
      dbg.pfnUserCallback = callback;
      dbg.pUserData = user;
      info.pNext = &dbg;  // also covers vkCreateInstance / vkDestroyInstance
    }
    {
      IRRADCAST_DRIVER_LEAKS_NOT_REPORTED;  // (through a layer, the driver enumerates here)
      check(vkCreateInstance(&info, nullptr, &handle), "vkCreateInstance");
    }
    if (validation) {
      auto create = reinterpret_cast<PFN_vkCreateDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(handle, "vkCreateDebugUtilsMessengerEXT"));
      if (!create) {
        vkDestroyInstance(handle, nullptr);
        throw Error("the validation layer offers no VK_EXT_debug_utils messenger");
      }
      check(create(handle, &dbg, nullptr, &messenger), "vkCreateDebugUtilsMessengerEXT");
    }
  }
  ~Instance() {
    if (messenger != VK_NULL_HANDLE) {
      auto destroy = reinterpret_cast<PFN_vkDestroyDebugUtilsMessengerEXT>(
          vkGetInstanceProcAddr(handle, "vkDestroyDebugUtilsMessengerEXT"));
      if (destroy) destroy(handle, messenger, nullptr);
    }
    if (handle != VK_NULL_HANDLE) vkDestroyInstance(handle, nullptr);
  }
  Instance(const Instance&) = delete;
  Instance& operator=(const Instance&) = delete;

  std::vector<VkPhysicalDevice> physical_devices() const {
    IRRADCAST_DRIVER_LEAKS_NOT_REPORTED;
    std::uint32_t n = 0;
    check(vkEnumeratePhysicalDevices(handle, &n, nullptr), "vkEnumeratePhysicalDevices");
    std::vector<VkPhysicalDevice> devices(n);
    check(vkEnumeratePhysicalDevices(handle, &n, devices.data()), "vkEnumeratePhysicalDevices");
    return devices;
  }
};

int compute_family(VkPhysicalDevice d) {
  std::uint32_t n = 0;
  vkGetPhysicalDeviceQueueFamilyProperties(d, &n, nullptr);
  std::vector<VkQueueFamilyProperties> families(n);
  vkGetPhysicalDeviceQueueFamilyProperties(d, &n, families.data());
  // Prefer a compute queue without graphics (a dedicated compute engine), else any compute.
  int any = -1;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (!(families[i].queueFlags & VK_QUEUE_COMPUTE_BIT)) continue;
    if (!(families[i].queueFlags & VK_QUEUE_GRAPHICS_BIT)) return static_cast<int>(i);
    if (any < 0) any = static_cast<int>(i);
  }
  return any;
}

VulkanDeviceInfo describe_device(VkPhysicalDevice d, std::uint32_t index) {
  VkPhysicalDeviceDriverProperties driver{};
  driver.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES;
  VkPhysicalDeviceProperties2 props{};
  props.sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2;
  VkPhysicalDeviceProperties basic{};
  vkGetPhysicalDeviceProperties(d, &basic);
  // Driver properties need Vulkan 1.2 on the device.
  if (basic.apiVersion >= VK_API_VERSION_1_2) props.pNext = &driver;
  vkGetPhysicalDeviceProperties2(d, &props);
  const VkPhysicalDeviceProperties& p = props.properties;
  VulkanDeviceInfo info;
  info.index = index;
  info.name = p.deviceName;
  info.type = type_name(p.deviceType);
  info.api_version = version_string(p.apiVersion);
  if (props.pNext) {
    info.driver = driver.driverName;
    if (driver.driverInfo[0]) info.driver += std::string(" ") + driver.driverInfo;
  }
  info.vendor_id = p.vendorID;
  info.device_id = p.deviceID;
  info.compute = compute_family(d) >= 0;
  info.max_workgroup_invocations = p.limits.maxComputeWorkGroupInvocations;
  info.max_storage_buffer_range = p.limits.maxStorageBufferRange;
  VkPhysicalDeviceMemoryProperties mem{};
  vkGetPhysicalDeviceMemoryProperties(d, &mem);
  for (std::uint32_t h = 0; h < mem.memoryHeapCount; ++h)
    if (mem.memoryHeaps[h].flags & VK_MEMORY_HEAP_DEVICE_LOCAL_BIT)
      info.device_memory += mem.memoryHeaps[h].size;
  return info;
}

}  // namespace

std::vector<VulkanDeviceInfo> list_vulkan_devices() {
  Instance instance(false, nullptr, nullptr);
  std::vector<VulkanDeviceInfo> out;
  const std::vector<VkPhysicalDevice> devices = instance.physical_devices();
  for (std::uint32_t i = 0; i < devices.size(); ++i) out.push_back(describe_device(devices[i], i));
  return out;
}

std::string describe(const VulkanDeviceInfo& d) {
  // Appended piece by piece: GCC 12 at -O3 sees an overlap in `"[" + std::to_string(...)`
  // (-Werror=restrict, GCC bug 105329).
  std::string s = "[";
  s += std::to_string(d.index);
  s += "] " + d.name + " (" + d.type + ", Vulkan " + d.api_version;
  if (!d.driver.empty()) s += ", " + d.driver;
  s += ", ";
  s += std::to_string(d.device_memory >> 20);
  s += " MiB device-local";
  s += d.compute ? ", compute)" : ", NO compute queue)";
  return s;
}

struct VulkanContext::Impl {
  static VKAPI_ATTR VkBool32 VKAPI_CALL on_message(VkDebugUtilsMessageSeverityFlagBitsEXT,
                                                   VkDebugUtilsMessageTypeFlagsEXT,
                                                   const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                   void* user) {
    auto* self = static_cast<Impl*>(user);
    std::lock_guard lock(self->log_mutex);
    ++self->messages;
    if (self->log.size() < 100)
      self->log.emplace_back(data && data->pMessage ? data->pMessage : "");
    return VK_FALSE;
  }

  explicit Impl(const VulkanContextOptions& o) : instance(o.validation, &on_message, this) {
    const std::vector<VkPhysicalDevice> devices = instance.physical_devices();
    if (devices.empty()) throw Error("Vulkan: no physical device");
    int chosen = -1;
    if (o.device >= 0) {
      if (o.device >= static_cast<int>(devices.size()))
        throw Error("Vulkan: there is no device " + std::to_string(o.device) + " (" +
                    std::to_string(devices.size()) + " found)");
      chosen = o.device;
    } else {
      int best_rank = 1 << 30;
      for (std::uint32_t i = 0; i < devices.size(); ++i) {
        const VulkanDeviceInfo d = describe_device(devices[i], i);
        if (d.compute && type_rank(d.type) < best_rank) {
          best_rank = type_rank(d.type);
          chosen = static_cast<int>(i);
        }
      }
      if (chosen < 0) throw Error("Vulkan: no device has a compute queue");
    }
    physical = devices[static_cast<std::size_t>(chosen)];
    info = describe_device(physical, static_cast<std::uint32_t>(chosen));
    const int family = compute_family(physical);
    if (family < 0) throw Error("Vulkan: " + info.name + " has no compute queue");
    queue_family = static_cast<std::uint32_t>(family);
    const float priority = 1.0f;
    VkDeviceQueueCreateInfo q{};
    q.sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO;
    q.queueFamilyIndex = queue_family;
    q.queueCount = 1;
    q.pQueuePriorities = &priority;
    VkDeviceCreateInfo dci{};
    dci.sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &q;
    check(vkCreateDevice(physical, &dci, nullptr, &device), "vkCreateDevice");
    vkGetDeviceQueue(device, queue_family, 0, &queue);
  }
  ~Impl() {
    if (device != VK_NULL_HANDLE) {
      vkDeviceWaitIdle(device);
      vkDestroyDevice(device, nullptr);
    }
  }

  mutable std::mutex log_mutex;
  std::uint64_t messages = 0;
  std::vector<std::string> log;
  Instance instance;  // after the log: the messenger may report while it is destroyed
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VulkanDeviceInfo info;
  std::uint32_t queue_family = 0;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
};

VulkanContext::VulkanContext(VulkanContextOptions options)
    : impl_(std::make_unique<Impl>(options)) {}

VulkanContext::~VulkanContext() = default;

const VulkanDeviceInfo& VulkanContext::device() const {
  return impl_->info;
}

std::uint32_t VulkanContext::queue_family() const {
  return impl_->queue_family;
}

std::uint64_t VulkanContext::validation_messages() const {
  std::lock_guard lock(impl_->log_mutex);
  return impl_->messages;
}

void vk_check(VkResult r, const char* what) {
  check(r, what);
}

VulkanHandles vulkan_handles(const VulkanContext& context) {
  const VulkanContext::Impl& i = context.impl();
  return VulkanHandles{i.physical, i.device, i.queue, i.queue_family};
}

std::vector<std::string> VulkanContext::validation_log() const {
  std::lock_guard lock(impl_->log_mutex);
  return impl_->log;
}

}  // namespace irradcast
