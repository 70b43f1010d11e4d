// Helpers of the CUDA backend's tests: why there is no device, and skipping a test visibly where there is none.
#pragma once

#include <string>

#include <gtest/gtest.h>

#include "compute/backend.h"

namespace mcslam::compute::test {

// Why there is no device, as one line starting "no CUDA device".
inline std::string NoDeviceMessage() {
  const std::string d = CudaDeviceDescription();
  return d.rfind("no CUDA device", 0) == 0 ? d : "no CUDA device: " + d;
}

}  // namespace mcslam::compute::test

// Skips the calling test, visibly, when there is no device to run it on.
#define REQUIRE_CUDA_DEVICE()                                                                        \
  do {                                                                                               \
    if (::mcslam::compute::CudaDeviceCount() == 0) GTEST_SKIP() << ::mcslam::compute::test::NoDeviceMessage(); \
  } while (0)
