// The particle filter's steps must not touch the heap once it is constructed (the benchmark's
// target and the guidance for estimators). This binary replaces the global operator new/delete
// with counting versions (forwarding to malloc/free).
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <new>

#include "estimators/estimator.h"
#include "estimators/kinematics/forward_kinematics.h"
#include "estimators/pf/particle_filter.h"
#include "tests/unit/pf/pf_test_models.h"

namespace {

std::atomic<long> g_allocations{0};

void* CountedAlloc(std::size_t size) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(size == 0 ? 1 : size)) return p;
  throw std::bad_alloc();
}

void* CountedAlignedAlloc(std::size_t size, std::align_val_t align) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  const std::size_t a = static_cast<std::size_t>(align);
  const std::size_t rounded = (size + a - 1) / a * a;
  if (void* p = std::aligned_alloc(a, rounded == 0 ? a : rounded)) return p;
  throw std::bad_alloc();
}

}  // namespace

void* operator new(std::size_t size) { return CountedAlloc(size); }
void* operator new[](std::size_t size) { return CountedAlloc(size); }
void* operator new(std::size_t size, std::align_val_t a) { return CountedAlignedAlloc(size, a); }
void* operator new[](std::size_t size, std::align_val_t a) { return CountedAlignedAlloc(size, a); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }

namespace flexbench::pf {
namespace {

template <class F>
long CountAllocations(const F& f) {
  const long before = g_allocations.load();
  f();
  return g_allocations.load() - before;
}

class NoAllocationTest : public ::testing::TestWithParam<Proposal> {};

TEST_P(NoAllocationTest, FilterStepsDoNotAllocate) {
  testing::JskLikeArm arm;
  ParticleFilterConfig c;
  c.position_frames = {arm.grasp};
  c.orientation_frames = {arm.imu2, arm.imu3};
  c.end_effector = arm.grasp;
  c.proposal = GetParam();
  ParticleFilter pf(arm.model, c, 1);
  Eigen::VectorXd q(4);
  q << 0.3, 0.6, 0.2, 0.0;
  kinematics::PpoeData data(arm.model);
  kinematics::ForwardKinematics(arm.model, data, q);
  const Quat q2(data.T_base_frame[arm.imu2].rotation());
  const Quat q3(data.T_base_frame[arm.imu3].rotation());
  const Vec3 p = data.T_base_frame[arm.grasp].translation();
  const long n = CountAllocations([&] {
    for (int step = 0; step < 5; ++step) {
      pf.Predict();
      pf.UpdateReference(q.data(), 4);
      pf.UpdateOrientation(arm.imu2, q2);
      pf.UpdateOrientation(arm.imu3, q3);
      pf.UpdatePosition(arm.grasp, Vec3::Zero(), p);
      pf.Summary();
      pf.StepLogLikelihood();
    }
    pf.Reset();
  });
  EXPECT_EQ(n, 0);
}

INSTANTIATE_TEST_SUITE_P(Proposals, NoAllocationTest,
                         ::testing::Values(Proposal::kBootstrap, Proposal::kEncoderConjugate));

}  // namespace
}  // namespace flexbench::pf
