// The memory of the adaptor's snapshot (snapshot.hpp): which pages of an array a step's copy
// touches, and an array copied in part that holds only those pages. Internal to the adaptor
// library.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <new>
#include <utility>
#include <vector>

#include <sys/mman.h>
#include <unistd.h>

namespace ldimesh {

// The pages of an array of `bytes` bytes that some of its stretches touch.
class PageSet {
 public:
  static std::size_t page() {
    static const std::size_t size = std::size_t(sysconf(_SC_PAGESIZE));
    return size;
  }
  explicit PageSet(std::size_t bytes = 0) : bytes_(bytes), marked_((bytes + page() - 1) / page()) {}
  // Bytes offset … offset + length − 1 are touched (any thread).
  void mark(std::size_t offset, std::size_t length) {
    if (length == 0) return;
    for (std::size_t p = offset / page(); p <= (offset + length - 1) / page(); ++p)
      std::atomic_ref<std::uint8_t>(marked_[p]).store(1, std::memory_order_relaxed);
  }
  bool marked(std::size_t p) const { return marked_[p] != 0; }
  std::size_t pages() const { return marked_.size(); }
  // f(first, end) for each run of touched pages first … end − 1 among pages from … to − 1.
  template <class F>
  void for_each_run(std::size_t from, std::size_t to, F&& f) const {
    for (std::size_t p = from; p < to;) {
      if (!marked_[p]) {
        ++p;
        continue;
      }
      const std::size_t first = p;
      while (p < to && marked_[p])
        ++p;
      f(first, p);
    }
  }
  // The bytes of the touched pages (the last one as far as the array goes).
  std::size_t bytes() const {
    std::size_t total = 0;
    for (std::size_t p = 0; p < marked_.size(); ++p)
      total += marked_[p] ? std::min(page(), bytes_ - p * page()) : 0;
    return total;
  }

 private:
  std::size_t bytes_;
  std::vector<std::uint8_t> marked_;
};

// One array of a block as copied at a due step (background path), of which a step may copy
// only some stretches (a grid block's needed bricks, an element block's needed elements):
// anonymous memory, kept from step to step so that later copies reuse its pages. Before a step
// writes, the pages it will not write are given back to the system, so the memory the array
// holds, during the copy as after it, is the pages the step copies into, not the whole array.
class SparseCopy {
 public:
  SparseCopy() = default;
  SparseCopy(SparseCopy&& other) noexcept { *this = std::move(other); }
  SparseCopy& operator=(SparseCopy&& other) noexcept {
    std::swap(data_, other.data_);
    std::swap(size_, other.size_);
    std::swap(held_, other.held_);
    return *this;
  }
  ~SparseCopy() { unmap(); }

  // Prepares the array of `bytes` bytes for a step that writes into the pages `planned` (of an
  // array of `bytes`): gives back the other pages it holds (a new mapping where the size
  // changed). Throws std::bad_alloc where the system refuses the memory.
  unsigned char* begin(std::size_t bytes, PageSet planned) {
    if (bytes != size_) {
      unmap();
      if (bytes > 0) {
        void* p = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
        if (p == MAP_FAILED) throw std::bad_alloc();
        // Small pages: a huge page would make one written stretch hold 2 MiB.
        advise_small_pages(p, bytes);
        data_ = static_cast<unsigned char*>(p);
      }
      size_ = bytes;
    } else {
      const std::size_t page = PageSet::page();
      for (std::size_t p = 0; p < held_.pages();) {
        if (!held_.marked(p) || planned.marked(p)) {
          ++p;
          continue;
        }
        const std::size_t first = p;
        while (p < held_.pages() && !planned.marked(p))
          ++p;
        madvise(data_ + first * page, std::min(p * page, size_) - first * page, MADV_DONTNEED);
      }
    }
    held_ = std::move(planned);
    return data_;
  }
  // What it holds: the pages of the last step's copy.
  std::size_t bytes() const { return held_.bytes(); }
  const PageSet& held() const { return held_; }
  // No copy: gives the memory back.
  void clear() { unmap(); }
  unsigned char* data() { return data_; }

 private:
  static void advise_small_pages([[maybe_unused]] void* p, [[maybe_unused]] std::size_t bytes) {
#ifdef MADV_NOHUGEPAGE
    madvise(p, bytes, MADV_NOHUGEPAGE);
#endif
  }
  void unmap() {
    if (data_) munmap(data_, size_);
    data_ = nullptr;
    size_ = 0;
    held_ = PageSet();
  }
  unsigned char* data_ = nullptr;
  std::size_t size_ = 0;
  PageSet held_;
};

}  // namespace ldimesh
