#include "ldimesh/core/raycast/fragment.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>
#include <string>
#include <tuple>

namespace ldimesh {

void widen_scalar_range(float& lo, float& hi, float a, float b) {
  if (!std::isnan(a)) lo = std::isnan(lo) ? a : std::min(lo, a);
  if (!std::isnan(b)) hi = std::isnan(hi) ? b : std::max(hi, b);
}

void fragment_scalar_range(const LdiFragment& f, float& lo, float& hi) {
  lo = f.scalar_lo;
  hi = f.scalar_hi;
  for (float x : f.scalar)
    if (std::isfinite(x)) widen_scalar_range(lo, hi, x, x);
}

LdiFragment make_empty_fragment(const View& view, std::uint32_t view_index) {
  LdiFragment f;
  f.view = view_index;
  f.pixel_count = view.pixel_count();
  f.depth_lo = 0.0;
  f.depth_hi = view.depth_extent;
  return f;
}

LdiFragment fragment_from_ldi(const Ldi& ldi, std::uint32_t view_index) {
  LdiFragment f = make_empty_fragment(ldi.view, view_index);
  for (std::size_t p = 0; p < ldi.pixel_count(); ++p)
    if (ldi.count(p) > 0) {
      f.pixels.push_back(std::uint32_t(p));
      f.counts.push_back(ldi.count(p));
    }
  f.depth = ldi.depth;
  f.normal = ldi.normal;
  f.scalar = ldi.scalar;
  return f;
}

Status validate_fragment(const LdiFragment& f) {
  if (f.pixels.size() != f.counts.size())
    return Status::corrupt_input("fragment: " + std::to_string(f.pixels.size()) +
                                 " pixel ids but " + std::to_string(f.counts.size()) + " counts");
  if (f.normal.size() != f.depth.size())
    return Status::corrupt_input("fragment: normals and depths differ in number");
  if (!f.scalar.empty() && f.scalar.size() != f.depth.size())
    return Status::corrupt_input("fragment: scalars and depths differ in number");
  if (!(f.depth_lo <= f.depth_hi) || !std::isfinite(f.depth_lo) || !std::isfinite(f.depth_hi))
    return Status::corrupt_input("fragment: invalid depth interval");
  if ((std::isnan(f.scalar_lo) != std::isnan(f.scalar_hi)) ||
      (!std::isnan(f.scalar_lo) && (!std::isfinite(f.scalar_lo) || !std::isfinite(f.scalar_hi) ||
                                    !(f.scalar_lo <= f.scalar_hi))))
    return Status::corrupt_input("fragment: invalid scalar range");
  std::uint64_t total = 0;
  for (std::size_t k = 0; k < f.pixels.size(); ++k) {
    if (f.pixels[k] >= f.pixel_count)
      return Status::corrupt_input("fragment: pixel id out of range");
    if (k > 0 && f.pixels[k] <= f.pixels[k - 1])
      return Status::corrupt_input("fragment: pixel ids not strictly increasing");
    if (f.counts[k] == 0) return Status::corrupt_input("fragment: a listed pixel has no sample");
    const std::uint64_t begin = total;
    total += f.counts[k];
    if (total > f.depth.size()) return Status::corrupt_input("fragment: counts exceed the samples");
    for (std::uint64_t s = begin; s < total; ++s) {
      if (!std::isfinite(f.depth[s])) return Status::corrupt_input("fragment: non-finite depth");
      if (s > begin && f.depth[s] < f.depth[s - 1])
        return Status::corrupt_input("fragment: depths of a pixel not sorted");
    }
  }
  if (total != f.depth.size())
    return Status::corrupt_input("fragment: counts do not sum to the samples");
  return Status::ok();
}

LdiFragment combine_fragments(std::span<const LdiFragment> fragments, double tolerance,
                              const glm::vec3& dir) {
  if (fragments.empty()) return {};
  const LdiFragment& first = fragments.front();
  LdiFragment out;
  out.view = first.view;
  out.pixel_count = first.pixel_count;
  out.depth_lo = first.depth_lo;
  out.depth_hi = first.depth_hi;
  const bool with_scalar = std::any_of(fragments.begin(), fragments.end(),
                                       [](const LdiFragment& f) { return !f.scalar.empty(); });
  for (const LdiFragment& f : fragments) {
    widen_scalar_range(out.scalar_lo, out.scalar_hi, f.scalar_lo, f.scalar_hi);
    if (f.view != first.view || f.pixel_count != first.pixel_count ||
        f.depth_lo != first.depth_lo || f.depth_hi != first.depth_hi)
      throw std::invalid_argument("combine_fragments: fragments of different views");
    if (!f.depth.empty() && f.scalar.empty() == with_scalar)
      throw std::invalid_argument("combine_fragments: some fragments carry a scalar, others not");
  }

  // A k-way merge over pixel ids: each fragment's cursor walks its pixels in increasing order.
  struct Cursor {
    std::size_t pixel = 0;   // index into pixels/counts
    std::size_t sample = 0;  // first sample of that pixel
  };
  std::vector<Cursor> cursors(fragments.size());
  struct Sample {
    float depth;
    glm::vec3 normal;
    float scalar;
  };
  std::vector<Sample> samples;
  while (true) {
    std::uint32_t next = UINT32_MAX;
    bool any = false;
    for (std::size_t k = 0; k < fragments.size(); ++k)
      if (cursors[k].pixel < fragments[k].pixels.size()) {
        next = std::min(next, fragments[k].pixels[cursors[k].pixel]);
        any = true;
      }
    if (!any) break;
    samples.clear();
    for (std::size_t k = 0; k < fragments.size(); ++k) {
      const LdiFragment& f = fragments[k];
      Cursor& c = cursors[k];
      if (c.pixel >= f.pixels.size() || f.pixels[c.pixel] != next) continue;
      for (std::size_t s = c.sample; s < c.sample + f.counts[c.pixel]; ++s)
        samples.push_back({f.depth[s], f.normal[s], with_scalar ? f.scalar[s] : 0.0f});
      c.sample += f.counts[c.pixel];
      ++c.pixel;
    }
    const std::size_t kept = collapse_duplicate_hits(
        std::span<Sample>(samples), tolerance, dir,
        [](const Sample& a, const Sample& b) {
          return std::tie(a.depth, a.normal.x, a.normal.y, a.normal.z, a.scalar) <
                 std::tie(b.depth, b.normal.x, b.normal.y, b.normal.z, b.scalar);
        },
        [](const Sample& s) { return s.depth; }, [](const Sample& s) { return s.normal; });
    for (std::size_t k = 0; k < kept; ++k) {
      out.depth.push_back(samples[k].depth);
      out.normal.push_back(samples[k].normal);
      if (with_scalar) out.scalar.push_back(samples[k].scalar);
    }
    out.pixels.push_back(next);
    out.counts.push_back(std::uint32_t(kept));
  }
  return out;
}

Ldi ldi_from_fragment(const LdiFragment& f, const View& view) {
  if (f.pixel_count != view.pixel_count())
    throw std::invalid_argument("ldi_from_fragment: the fragment is of a view with " +
                                std::to_string(f.pixel_count) + " pixels, not " +
                                std::to_string(view.pixel_count()));
  Ldi ldi = make_empty_ldi(view);
  for (std::size_t k = 0; k < f.pixels.size(); ++k)
    ldi.offsets[f.pixels[k] + 1] = f.counts[k];
  std::partial_sum(ldi.offsets.begin(), ldi.offsets.end(), ldi.offsets.begin());
  ldi.depth = f.depth;
  ldi.normal = f.normal;
  ldi.scalar = f.scalar;
  return ldi;
}

}  // namespace ldimesh
