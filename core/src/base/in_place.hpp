// Internal to the core: writing an output over the input's own arrays (merging's and the quad
// conversion's outputs, docs/method.md "Output in place").
#pragma once

#include <cstddef>
#include <vector>

namespace ldimesh {

// array[at] = value, or appended when `at` is the end: an entry written at or below the place
// it is read from (or past the end) never overwrites one still to be read.
template <class T, class U>
void put_at(std::vector<T>& array, std::size_t at, const U& value) {
  if (at < array.size()) {
    array[at] = value;
  } else {
    array.push_back(value);
  }
}

}  // namespace ldimesh
