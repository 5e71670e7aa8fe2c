// The C++ adaptor under mpiexec, as a solver uses it. Collective tests: every rank runs every
// test and only non-fatal EXPECTs are used, so that no rank is left alone in a collective call.
#include <mpi.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include <gtest/gtest.h>

#include "../mpi/mpi_gtest.hpp"
#include "ldimesh/adaptor.hpp"
#include "ldimesh/core/decomposition.hpp"
#include "ldimesh/core/surfaces.hpp"
#include "published_step.hpp"

namespace ldimesh {
namespace {

using testing::rank_of;
using testing::ranks;

// An adaptor over the built-in `surface`, this rank's block of its domain.
std::unique_ptr<Adaptor> make(const std::string& options, const char* surface = "sphere") {
  std::unique_ptr<Adaptor> a;
  const Status s = Adaptor::create(MPI_COMM_WORLD, options, a);
  EXPECT_TRUE(s) << s.message();
  if (!a) return a;
  const SurfaceInfo* info = find_surface(surface);
  EXPECT_TRUE(a->set_domain(info->domain));
  EXPECT_TRUE(
      a->add_source(make_surface_source(surface), decompose_box(info->domain, ranks())[rank_of()]));
  return a;
}

std::string temp_dir(const std::string& name) {
  return testing::fresh_temp_dir("ldimesh_adaptor", name);
}

TEST(Adaptor, InvalidOptionsAreReportedOnEveryRankWithTheKey) {
  std::unique_ptr<Adaptor> a;
  Status s = Adaptor::create(MPI_COMM_WORLD, R"({"resolutin": 64})", a);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("resolutin"), std::string::npos) << s.message();
  EXPECT_EQ(a, nullptr);
  s = Adaptor::create(MPI_COMM_WORLD, R"({"r": 2})", a);
  EXPECT_NE(s.message().find("'r'"), std::string::npos) << s.message();
  s = Adaptor::create(MPI_COMM_WORLD, R"({"cadence": {"every_steps": 0}})", a);
  EXPECT_NE(s.message().find("cadence.every_steps"), std::string::npos) << s.message();
  s = Adaptor::create(MPI_COMM_WORLD, "{not json", a);
  EXPECT_FALSE(s);
  s = Adaptor::create(MPI_COMM_WORLD, R"({"refinement": true})", a);
  EXPECT_NE(s.message().find("refinement"), std::string::npos) << s.message();
}

TEST(Adaptor, DueStepsArePublishedAndWrittenOffTheSolversPath) {
  const std::string dir = temp_dir("publish");
  // "coalesce": a due step the busy root cannot take yet waits, replacing an older waiting
  // one, so the newest due step is always published.
  auto a =
      make(R"({"server": {"enabled": false}, "resolution": 48, "log": false, "busy": "coalesce",
                    "cadence": {"every_steps": 2}, "output_dir": ")" +
           dir + R"("})");
  if (!a) return;
  for (std::uint64_t step = 0; step < 6; ++step)
    EXPECT_TRUE(a->execute(step, 0.1 * double(step)));
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_GE(a->published_steps(), 1u);
    EXPECT_TRUE(std::filesystem::exists(dir + "/step_000004.glb"));  // the newest due step
    EXPECT_TRUE(std::filesystem::exists(dir + "/step_000004.json"));
    EXPECT_FALSE(std::filesystem::exists(dir + "/step_000001.glb"));  // not due
    EXPECT_FALSE(std::filesystem::exists(dir + "/step_000005.glb"));
  }
}

TEST(Adaptor, ASlowRootMakesStepsBeSkippedNotTheSolverWait) {
  const std::string dir = temp_dir("slow");
  auto a = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "busy": "skip",
                    "testing": {"slow_root_seconds": 0.4}, "output_dir": ")" +
                dir + R"("})");
  if (!a) return;
  int skipped = 0, skipped_since_handoff = 0;
  double worst = 0.0;
  for (std::uint64_t step = 0; step < 5; ++step) {
    EXPECT_TRUE(a->execute(step, 0.0));
    if (a->last_report().skipped_busy) {
      ++skipped;
      ++skipped_since_handoff;
    } else {
      skipped_since_handoff = 0;
    }
    worst = std::max(worst, a->last_report().blocked_seconds);
  }
  // Once the worker is idle again the next step is published and counts the steps dropped
  // since the last one handed over.
  std::this_thread::sleep_for(std::chrono::milliseconds(900));
  EXPECT_TRUE(a->execute(5, 0.0));
  EXPECT_FALSE(a->last_report().skipped_busy);
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_GE(skipped, 3);   // the worker sleeps 0.4 s per step, the solver does not
    EXPECT_LT(worst, 0.35);  // no execute() waited for the worker
    EXPECT_LE(a->published_steps(), 3u);
    EXPECT_EQ(testing::published_step(dir, 5).skipped_steps, std::uint64_t(skipped_since_handoff));
  }
}

TEST(Adaptor, AStepWithoutSurfaceIsPublishedEmpty) {
  auto a =
      make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "isovalues": [100]})");
  if (!a) return;
  EXPECT_TRUE(a->execute(0, 0.0));
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    EXPECT_EQ(a->published_steps(), 1u);
  }
}

// "merging": the root publishes one merged mesh (§5): for the sphere a closed triangle mesh,
// so its counts satisfy Euler's V − E + F = 2 with E = 3F/2, i.e. F = 2 (V − 2).
TEST(Adaptor, MergingPublishesOneClosedMesh) {
  const std::string dir = temp_dir("merging");
  auto a = make(R"({"server": {"enabled": false}, "resolution": 32, "log": false, "isovalues": [1],
                    "merging": true, "output_dir": ")" +
                dir + R"("})");
  if (!a) return;
  EXPECT_TRUE(a->execute(0, 0.0));
  EXPECT_TRUE(a->finalize());
  if (rank_of() == 0) {
    const StepMetadata meta = testing::published_step(dir, 0);
    EXPECT_GT(meta.triangles, 1000u);
    EXPECT_EQ(meta.triangles, 2 * (meta.vertices - 2));
  }
}

TEST(Adaptor, ExecuteWithoutADomainFailsCleanly) {
  std::unique_ptr<Adaptor> a;
  EXPECT_TRUE(
      Adaptor::create(MPI_COMM_WORLD, R"({"server": {"enabled": false}, "log": false})", a));
  if (!a) return;
  const Status s = a->execute(0, 0.0);
  EXPECT_FALSE(s);
  EXPECT_NE(s.message().find("set_domain"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace ldimesh

int main(int argc, char** argv) {
  return ldimesh::testing::run_mpi_tests(argc, argv);
}
