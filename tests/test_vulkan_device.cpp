// The Vulkan device layer of the GPU backend (issue 6, in progress): lavapipe, which
// deploy/install-deps.sh installs, must be found and opened with the validation layer on and
// no validation message; without a driver the error says so.
#include <gtest/gtest.h>

#include "cli.h"
#include "irradcast/common/error.h"
#include "irradcast/engine/vulkan_device.h"

namespace irradcast::test_vulkan_device {

TEST(Vulkan, FindsADeviceWithComputeOnThisMachine) {
  const std::vector<VulkanDeviceInfo> devices = list_vulkan_devices();
  ASSERT_FALSE(devices.empty()) << "no Vulkan device: is mesa-vulkan-drivers (lavapipe) installed?";
  bool compute = false;
  for (const VulkanDeviceInfo& d : devices) {
    EXPECT_FALSE(d.name.empty());
    EXPECT_NE(describe(d).find(d.name), std::string::npos);
    compute = compute || d.compute;
  }
  EXPECT_TRUE(compute);
}

TEST(Vulkan, OpensTheBestDeviceWithValidationAndNoMessages) {
  VulkanContextOptions o;
  o.validation = true;
  {
    VulkanContext ctx(o);
    EXPECT_TRUE(ctx.device().compute);
    EXPECT_GT(ctx.device().max_workgroup_invocations, 0u);
    EXPECT_EQ(ctx.validation_messages(), 0u)
        << (ctx.validation_log().empty() ? "" : ctx.validation_log().front());
    RecordProperty("device", describe(ctx.device()));
  }
  o.device = 1000;
  try {
    VulkanContext bad(o);
    ADD_FAILURE() << "device 1000 was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("there is no device 1000"), std::string::npos) << e.what();
  }
}

TEST(Vulkan, ListDevicesNamesVulkanAndEmbreeAndSaysWhyVulkanIsMissing) {
  const test::CliResult ok = test::run_cli(IRRADCAST_SERVER_EXE, "--list-devices");
  EXPECT_EQ(ok.status, 0) << ok.output;
  EXPECT_NE(ok.output.find("embree: the CPU"), std::string::npos) << ok.output;
  EXPECT_NE(ok.output.find("vulkan: ["), std::string::npos) << ok.output;
  EXPECT_NE(ok.output.find("--backend auto: "), std::string::npos) << ok.output;
  // No driver: the loader finds no ICD.
  const test::CliResult none =
      test::run_cli(std::string("VK_ICD_FILENAMES=/nonexistent/icd.json ") + IRRADCAST_SERVER_EXE,
                    "--list-devices");
  EXPECT_EQ(none.status, 0) << none.output;
  EXPECT_NE(none.output.find("embree: the CPU"), std::string::npos) << none.output;
  EXPECT_NE(
      none.output.find("vulkan: not available: vkCreateInstance: VK_ERROR_INCOMPATIBLE_DRIVER"),
      std::string::npos)
      << none.output;
  EXPECT_NE(none.output.find("--backend auto: embree (no Vulkan GPU)"), std::string::npos)
      << none.output;
}

}  // namespace irradcast::test_vulkan_device
