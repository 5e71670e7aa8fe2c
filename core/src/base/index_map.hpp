// Internal to the core: an open-addressing hash map from keys to indices, and the hash mix it
// is used with (the refiner's edges and positions, the crossing check's grid cells).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "mesh_util.hpp"

namespace ldimesh {

// A 64-bit mix (MurmurHash3's finaliser): IndexMap takes the low bits, and the keys (vertex
// pairs, dyadic image positions, packed grid cells) differ in few bits, often high ones.
inline std::uint64_t mix(std::uint64_t x) {
  x ^= x >> 33;
  x *= 0xFF51AFD7ED558CCDull;
  x ^= x >> 33;
  x *= 0xC4CEB9FE1A85EC53ull;
  return x ^ (x >> 33);
}

struct MixHash {
  std::uint64_t operator()(std::uint64_t key) const { return mix(key); }
};

// A hash map from keys to indices, open addressing with linear probing in one array (at most
// half full). The refiner looks up and adds millions of edges and positions in a run; a node per
// entry (std::unordered_map) made allocating, chasing and freeing them a large part of its time.
// Indices are below UINT32_MAX (the empty slot).
template <class Key, class Hash>
class IndexMap {
 public:
  // The index stored under `key`, or kNone.
  std::uint32_t find(const Key& key) const {
    if (slots_.empty()) return kNone;
    for (std::size_t i = Hash()(key) & mask_;; i = (i + 1) & mask_) {
      const Slot& slot = slots_[i];
      if (slot.index == kNone) return kNone;
      if (slot.key == key) return slot.index;
    }
  }

  // The index stored under `key`, and whether it is `index`, stored now because there was none.
  std::pair<std::uint32_t, bool> try_emplace(const Key& key, std::uint32_t index) {
    if (2 * (count_ + 1) > slots_.size()) reserve(count_ + 1);
    for (std::size_t i = Hash()(key) & mask_;; i = (i + 1) & mask_) {
      Slot& slot = slots_[i];
      if (slot.index == kNone) {
        slot = {key, index};
        ++count_;
        return {index, true};
      }
      if (slot.key == key) return {slot.index, false};
    }
  }

  // Room for `count` entries without rehashing.
  void reserve(std::size_t count) {
    std::size_t capacity = 64;
    while (capacity < 2 * count)
      capacity *= 2;
    if (capacity > slots_.size()) rehash(capacity);
  }

  // Empties the map and keeps its memory.
  void clear() {
    for (Slot& slot : slots_)
      slot.index = kNone;
    count_ = 0;
  }

 private:
  struct Slot {
    Key key{};
    std::uint32_t index = kNone;
  };

  void rehash(std::size_t capacity) {
    std::vector<Slot> old(capacity);
    old.swap(slots_);
    mask_ = capacity - 1;
    count_ = 0;
    for (const Slot& slot : old)
      if (slot.index != kNone) try_emplace(slot.key, slot.index);
  }

  std::vector<Slot> slots_;  // capacity a power of two
  std::size_t mask_ = 0, count_ = 0;
};

}  // namespace ldimesh
