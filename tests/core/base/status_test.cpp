#include "ldimesh/core/base/status.hpp"

#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace ldimesh {
namespace {

StatusOr<std::vector<int>> count_to(int n) {
  if (n < 0) return Status::invalid_argument("count_to: negative");
  std::vector<int> v;
  for (int i = 1; i <= n; ++i)
    v.push_back(i);
  return v;
}

// Adds the lengths of count_to(a) and count_to(b), or returns the first failure.
StatusOr<std::size_t> both(int a, int b) {
  LDIMESH_ASSIGN_OR_RETURN(const std::vector<int> first, count_to(a));
  LDIMESH_ASSIGN_OR_RETURN(const std::vector<int> second, count_to(b));
  return first.size() + second.size();
}

TEST(StatusOr, HoldsTheValueOrTheFailure) {
  const StatusOr<std::vector<int>> three = count_to(3);
  ASSERT_TRUE(three.ok());
  EXPECT_TRUE(three.status());
  EXPECT_EQ(*three, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(three->size(), 3u);

  const StatusOr<std::vector<int>> none = count_to(-1);
  EXPECT_FALSE(none.ok());
  EXPECT_FALSE(bool(none));
  EXPECT_EQ(none.status().code(), StatusCode::invalid_argument);
  EXPECT_EQ(none.status().message(), "count_to: negative");
}

TEST(StatusOr, AssignOrReturnStopsAtTheFirstFailure) {
  const StatusOr<std::size_t> five = both(2, 3);
  ASSERT_TRUE(five.ok()) << five.status().message();
  EXPECT_EQ(*five, 5u);
  const StatusOr<std::size_t> failed = both(2, -4);
  ASSERT_FALSE(failed.ok());
  EXPECT_EQ(failed.status().message(), "count_to: negative");
}

TEST(StatusOr, MovesOnlyTypesOut) {
  StatusOr<std::unique_ptr<int>> p = std::make_unique<int>(7);
  ASSERT_TRUE(p.ok());
  const std::unique_ptr<int> taken = std::move(p).value();
  ASSERT_TRUE(taken);
  EXPECT_EQ(*taken, 7);
}

}  // namespace
}  // namespace ldimesh
