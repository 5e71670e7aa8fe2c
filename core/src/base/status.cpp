#include "ldimesh/core/base/status.hpp"

#include <exception>
#include <new>
#include <stdexcept>

namespace ldimesh {

const char* to_string(StatusCode code) {
  switch (code) {
    case StatusCode::ok:
      return "ok";
    case StatusCode::invalid_argument:
      return "invalid argument";
    case StatusCode::invalid_options:
      return "invalid options";
    case StatusCode::corrupt_input:
      return "corrupt input";
    case StatusCode::io:
      return "I/O error";
    case StatusCode::out_of_memory:
      return "out of memory";
    case StatusCode::other_rank:
      return "failed on another rank";
    case StatusCode::internal:
      return "internal error";
  }
  return "unknown status code";
}

Status status_from_current_exception(std::string_view where) {
  const std::string prefix(where);
  try {
    throw;
  } catch (const std::bad_alloc&) {
    return Status::out_of_memory(prefix + "out of memory");
  } catch (const std::invalid_argument& e) {
    return Status::invalid_argument(prefix + e.what());
  } catch (const std::exception& e) {
    return Status::internal(prefix + e.what());
  } catch (...) {
    return Status::internal(prefix + "an exception of unknown type");
  }
}

}  // namespace ldimesh
