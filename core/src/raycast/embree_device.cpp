#include <string>

#include "ldimesh/core/field/field_source.hpp"

namespace ldimesh {
namespace {

// The last message Embree gave on this thread (Embree calls the error function on the thread
// whose API call failed).
thread_local std::string last_message;

void keep_message(void*, RTCError, const char* message) {
  last_message = message ? message : "";
}

}  // namespace

RTCDevice make_embree_device() {
  last_message.clear();
  RTCDevice device = rtcNewDevice(nullptr);
  if (!device) {
    const RTCError code = rtcGetDeviceError(nullptr);
    throw std::runtime_error("Embree: cannot create a device (RTCError " +
                             std::to_string(int(code)) + ")");
  }
  rtcSetDeviceErrorFunction(device, keep_message, nullptr);
  return device;
}

std::string embree_failure(RTCDevice device, const std::string& what) {
  const RTCError code = rtcGetDeviceError(device);
  if (code == RTC_ERROR_NONE) return {};
  std::string line = "Embree: " + what + " failed";
  if (!last_message.empty()) line += ": " + last_message;
  line += " (RTCError " + std::to_string(int(code)) + ")";
  last_message.clear();
  return line;
}

}  // namespace ldimesh
