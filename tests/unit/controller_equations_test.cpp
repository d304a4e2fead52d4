// Seed 000 §3.4 Eq. 4-7 pinned by hand-computed values (latencies in seconds, sizes in bytes), Fig. 4's two
// curves reproduced as data, the modes, and parameter validation.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "texstream/stream/adaptive_controller.hpp"

namespace texstream {
namespace {

using C = stream::AdaptiveController;

// Table 2 in mode seed: these tests pin the seed's equations (mode auto has controller_headroom_test.cpp).
stream::ControllerParams seed_params() {
  stream::ControllerParams p;
  p.mode = ControllerMode::kSeed;
  return p;
}

stream::AdaptiveController make(const stream::ControllerParams& p = seed_params()) {
  auto c = C::create(p);
  EXPECT_TRUE(c.ok()) << (c.ok() ? "" : c.error().message);
  return std::move(*c);
}

TEST(ControllerEquations, PolynomialByHand) {
  // P(0.01) = 0.01 + 0.1^2 + 0.3^3 + 0.5^4 = 0.01 + 0.01 + 0.027 + 0.0625 = 0.1095
  EXPECT_NEAR(C::load_polynomial(0.01), 0.1095, 1e-15);
  EXPECT_NEAR(C::load_polynomial(-0.01), 0.1095, 1e-15);  // |x|
  // P(0.02) = 0.02 + 0.04 + 0.216 + 1 = 1.276 (the quartic term reaches 1 at |x| = 20 ms)
  EXPECT_NEAR(C::load_polynomial(0.02), 1.276, 1e-14);
  EXPECT_EQ(C::load_polynomial(0.0), 0.0);
  // Step: sign(-x) P Δt. x = +10 ms, Δt = 16 ms: -0.1095 * 0.016 = -0.001752.
  EXPECT_NEAR(C::load_factor_step(0.01, 0.016), -0.001752, 1e-16);
  EXPECT_NEAR(C::load_factor_step(-0.01, 0.016), 0.001752, 1e-16);
  EXPECT_EQ(C::load_factor_step(0.0, 0.016), 0.0);  // sign(0) = 0: l holds
}

TEST(ControllerEquations, WeightedLatencyByHand) {
  // Rise: Δt above t_w is taken at once. d = max(0.01 - 0.05, 0) = 0 → t_w = max(0.01, 0.05) = 0.05.
  EXPECT_DOUBLE_EQ(C::weighted_latency(0.01, 0.05), 0.05);
  // Decay: t_w = 0.1, Δt = 0.01 → d = 0.09, (30 · 0.09)^2 · 0.01 = 2.7^2 · 0.01 = 0.0729 → t_w = 0.0271.
  EXPECT_NEAR(C::weighted_latency(0.1, 0.01), 0.0271, 1e-15);
  // A decay larger than the gap stops at Δt: t_w = 1, Δt = 0.1 → d = 0.9, 27^2 · 0.1 = 72.9 → max(-71.9, 0.1).
  EXPECT_DOUBLE_EQ(C::weighted_latency(1.0, 0.1), 0.1);
  // A small gap decays slowly: t_w = 0.012, Δt = 0.010 → d = 0.002, 0.06^2 · 0.01 = 3.6e-5 → 0.011964.
  EXPECT_NEAR(C::weighted_latency(0.012, 0.010), 0.011964, 1e-15);
}

TEST(ControllerEquations, ThresholdByHand) {
  // t_wa <= α: halfway. 0.5 · 0.010 + 0.5 · 0.016 = 0.013.
  EXPECT_NEAR(C::threshold(0.010, 0.016), 0.013, 1e-15);
  // t_wa > α: 0.85 toward α. 0.15 · 0.020 + 0.85 · 0.016 = 0.003 + 0.0136 = 0.0166.
  EXPECT_NEAR(C::threshold(0.020, 0.016), 0.0166, 1e-15);
  // Equal: the "otherwise" branch: 0.016.
  EXPECT_NEAR(C::threshold(0.016, 0.016), 0.016, 1e-15);
}

TEST(ControllerEquations, BiasByHand) {
  // t_bl = t_bu = t_b = 10 ms: smoothstep(0.0096, 0.012, 0.010): t = 0.0004 / 0.0024 = 1/6,
  // t^2 (3 - 2t) = (1/36)(8/3) = 2/27 → b = 8 · 2/27 = 16/27 = 0.592593 (the steady-state bias).
  EXPECT_NEAR(C::mip_bias(8, 0.010, 0.010, 0.010), 16.0 / 27.0, 1e-12);
  EXPECT_EQ(C::mip_bias(8, 0.010, 0.010, 0.005), 0.0);  // below 0.96 t_bl
  EXPECT_EQ(C::mip_bias(8, 0.010, 0.010, 0.013), 8.0);  // above 1.2 t_bu
  EXPECT_EQ(C::smoothstep(0.0, 0.0, 0.0), 0.0);         // degenerate edges (all t_w = 0): no bias
  EXPECT_EQ(C::smoothstep(1.0, 0.5, 2.0), 0.0);
}

// Δt = 10, 10, 40, 10 ms with Table 2 (α = 16 ms, β = 8, s_min = 65000 B, s_max = 64e6 B), from a fresh state
// (t_w = 0, l = 0, empty windows). Hand computation:
// frame 1: d = 0, t_w = max(0, 0.010) = 0.010. t_wa: no previous t_w → t_w = 0.010 (<= α) →
//   t_m = 0.5·0.010 + 0.5·0.016 = 0.013; x = -0.003; P = 0.003 + 0.03^2 + 0.09^3 + 0.15^4
//   = 0.003 + 0.0009 + 0.000729 + 0.00050625 = 0.00513525; l = 0 + 0.00513525 · 0.010 = 5.13525e-5;
//   s = max(5.13525e-5 · 64e6 = 3286.56, 65000) = 65000. t_b = t_bl = t_bu = t_w = 0.010 (no history) →
//   b = 16/27 (BiasByHand).
// frame 2: d = 0, t_w = 0.010; t_wa = mean{0.010} = 0.010 → same x → l = 2 · 5.13525e-5 = 1.02705e-4.
//   t_bl = 0.2·0.010 + 0.8·min(0.010, 0.010) = 0.010 = t_bu; t_b = 0.010 → b = 16/27.
// frame 3: d = max(0.010 - 0.040, 0) = 0, t_w = 0.040. t_wa = 0.010 → t_m = 0.013; x = 0.027;
//   P = 0.027 + 0.27^2 + 0.81^3 + 1.35^4 = 0.027 + 0.0729 + 0.531441 + 3.32150625 = 3.95284725;
//   l = 1.02705e-4 - 3.95284725 · 0.040 < 0 → 0; s = 65000. t_b = mean{0.010, 0.010} = 0.010;
//   t_bl = 0.2·0.040 + 0.8·mean{min(0.010, 0.040) ×2} = 0.008 + 0.008 = 0.016;
//   t_bu = 0.008 + 0.8·mean{max(0.010, 0.040) ×2} = 0.008 + 0.032 = 0.040;
//   b = 8 · smoothstep(0.01536, 0.048, 0.010) = 0 (t_b below the lower edge).
// frame 4: d = 0.040 - 0.010 = 0.030, (30·0.030)^2 · 0.010 = 0.81 · 0.010 = 0.0081 → t_w = 0.0319.
//   t_wa = mean{0.010, 0.010, 0.040} = 0.020 > α → t_m = 0.15·0.020 + 0.85·0.016 = 0.0166; x = 0.0153 → l = 0.
//   t_b = 0.020. t_bl = 0.2·0.0319 + 0.8·mean{0.010, 0.010, min(0.016, 0.0319)} = 0.00638 + 0.8·0.012 = 0.01598;
//   t_bu = 0.00638 + 0.8·mean{0.0319, 0.0319, max(0.040, 0.0319)} = 0.00638 + 0.8·0.0346 = 0.03406;
//   b = 8·smoothstep(0.96·0.01598 = 0.0153408, 1.2·0.03406 = 0.040872, 0.020):
//   t = 0.0046592 / 0.0255312 = 0.1824904, t^2 (3 - 2t) = 0.0333027 · 2.6350192 = 0.0877534 → b = 0.7020273.
TEST(ControllerSequence, FourFramesByHand) {
  stream::AdaptiveController c = make();
  EXPECT_EQ(c.load_size_bytes(), 65000.0);  // before any frame: l = 0 → s_min
  EXPECT_EQ(c.mip_bias(), 0.0);

  ASSERT_TRUE(c.on_frame(0.010));
  EXPECT_NEAR(c.state().t_w, 0.010, 1e-15);
  EXPECT_NEAR(c.state().t_m, 0.013, 1e-15);
  EXPECT_NEAR(c.state().x, -0.003, 1e-15);
  EXPECT_NEAR(c.load_factor(), 5.13525e-5, 1e-17);
  EXPECT_EQ(c.load_size_bytes(), 65000.0);
  EXPECT_NEAR(c.mip_bias(), 16.0 / 27.0, 1e-12);

  ASSERT_TRUE(c.on_frame(0.010));
  EXPECT_NEAR(c.load_factor(), 1.02705e-4, 1e-17);
  EXPECT_NEAR(c.mip_bias(), 16.0 / 27.0, 1e-12);

  ASSERT_TRUE(c.on_frame(0.040));
  EXPECT_NEAR(c.state().t_w, 0.040, 1e-15);
  EXPECT_NEAR(c.state().x, 0.027, 1e-15);
  EXPECT_EQ(c.load_factor(), 0.0);
  EXPECT_NEAR(c.state().t_bl, 0.016, 1e-15);
  EXPECT_NEAR(c.state().t_bu, 0.040, 1e-15);
  EXPECT_EQ(c.mip_bias(), 0.0);

  ASSERT_TRUE(c.on_frame(0.010));
  EXPECT_NEAR(c.state().t_w, 0.0319, 1e-15);
  EXPECT_NEAR(c.state().t_wa, 0.020, 1e-15);
  EXPECT_NEAR(c.state().t_m, 0.0166, 1e-15);
  EXPECT_NEAR(c.state().x, 0.0153, 1e-15);
  EXPECT_EQ(c.load_factor(), 0.0);
  EXPECT_NEAR(c.state().t_b, 0.020, 1e-15);
  EXPECT_NEAR(c.state().t_bl, 0.01598, 1e-15);
  EXPECT_NEAR(c.state().t_bu, 0.03406, 1e-15);
  EXPECT_NEAR(c.mip_bias(), 0.7020273, 1e-6);
  EXPECT_EQ(c.frames_accepted(), 4u);
}

// Constant Δt = 5 ms, α = 16 ms: t_w = t_wa = 0.005 every frame, t_m = 0.5·0.005 + 0.5·0.016 = 0.0105,
// x = -0.0055, P = 0.0055 + 0.055^2 + 0.165^3 + 0.275^4 = 0.0055 + 0.003025 + 0.004492125 + 0.005719140625
// = 0.018736265625, Δl = P · 0.005 = 9.3681328125e-5 per frame: after 1000 frames l = 0.093681328125 and
// s = l · 64e6 = 5995605 bytes. Streaming ramps up steadily while the frame latency stays low (Fig. 4 left).
TEST(ControllerSequence, SteadyRampByHand) {
  stream::AdaptiveController c = make();
  for (int i = 0; i < 1000; ++i) ASSERT_TRUE(c.on_frame(0.005));
  EXPECT_NEAR(c.load_factor(), 0.093681328125, 1e-12);
  EXPECT_NEAR(c.load_size_bytes(), 5995605.0, 1.0);
  EXPECT_EQ(c.load_bytes(), static_cast<uint64_t>(c.load_size_bytes()));
  // A 100 ms spike: x ≈ 0.1 - 0.0105 ≈ 0.0895, P ≈ 0.0895 + 0.80 + 19.4 + 401 ≈ 421, · 0.1 = 42 ≫ l → l = 0.
  ASSERT_TRUE(c.on_frame(0.100));
  EXPECT_EQ(c.load_factor(), 0.0);
  EXPECT_EQ(c.load_size_bytes(), 65000.0);
}

// Fig. 4 left: Δl = sign(-x) P Δt against x with Δt = 1 ms. Odd, zero at 0, strictly decreasing, and
// steep past ±20 ms (the quartic term): at x = ±50 ms the step is ∓P(0.05)·0.001 = ∓0.0427375.
TEST(ControllerFigure4, LoadFactorCurve) {
  std::vector<double> xs, dl;
  for (int i = -50; i <= 50; ++i) {
    xs.push_back(i * 0.001);
    dl.push_back(C::load_factor_step(xs.back(), 0.001));
  }
  for (size_t i = 1; i < dl.size(); ++i) EXPECT_LT(dl[i], dl[i - 1]) << "x = " << xs[i];
  for (size_t i = 0; i < dl.size(); ++i) EXPECT_NEAR(dl[i], -dl[dl.size() - 1 - i], 1e-18);
  EXPECT_EQ(dl[50], 0.0);
  // P(0.05) = 0.05 + 0.25 + 3.375 + 39.0625 = 42.7375
  EXPECT_NEAR(dl.front(), 0.0427375, 1e-12);
  EXPECT_NEAR(dl.back(), -0.0427375, 1e-12);
  // Near zero the linear term dominates: x = -1 ms → P = 0.001 + 0.0001 + 0.000027 + 0.00000625 = 0.00113325.
  EXPECT_NEAR(dl[49], 0.00113325e-3, 1e-15);
}

// Fig. 4 right: b against t_b with β = 4, t_bl = 0, t_bu = 16.67 ms: b = 4 · smoothstep(0, 20.004 ms, t_b).
// 0 at t_b = 0, 2 at the midpoint 10.002 ms, 4 from 20.004 ms on; non-decreasing, strictly inside.
TEST(ControllerFigure4, BiasCurve) {
  const double t_bu = 0.01667, upper = 1.2 * t_bu;
  std::vector<double> tb, b;
  for (int i = 0; i <= 250; ++i) {
    tb.push_back(i * 0.0001);
    b.push_back(C::mip_bias(4.0, 0.0, t_bu, tb.back()));
  }
  EXPECT_EQ(b.front(), 0.0);
  EXPECT_EQ(b.back(), 4.0);
  for (size_t i = 1; i < b.size(); ++i) {
    if (tb[i] <= upper) {
      EXPECT_GT(b[i], b[i - 1]) << "t_b = " << tb[i];
    } else {
      EXPECT_EQ(b[i], 4.0) << "t_b = " << tb[i];
    }
  }
  EXPECT_NEAR(C::mip_bias(4.0, 0.0, t_bu, upper / 2), 2.0, 1e-12);
  // t_b = 5 ms: t = 0.005 / 0.020004 = 0.249950, t^2 (3 - 2t) = 0.0624750 · 2.5001 = 0.1561937 → b = 0.624775.
  EXPECT_NEAR(C::mip_bias(4.0, 0.0, t_bu, 0.005), 0.624775, 1e-5);
}

TEST(ControllerInput, RejectsBadInputWithoutChangingState) {
  stream::AdaptiveController c = make();
  for (int i = 0; i < 50; ++i) ASSERT_TRUE(c.on_frame(0.004 + 0.001 * (i % 7)));
  const stream::AdaptiveController::State before = c.state();
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(),
                        std::numeric_limits<double>::infinity(),
                        -std::numeric_limits<double>::infinity(),
                        -1e-9,
                        -10.0,
                        3600.0001,
                        1e300};
  for (double v : bad) {
    EXPECT_FALSE(c.on_frame(v)) << v;
    EXPECT_TRUE(c.state() == before) << v;
  }
  EXPECT_EQ(c.frames_rejected(), 7u);
  EXPECT_EQ(c.frames_accepted(), 50u);
  // Accepted edge cases: 0, -0.0, a denormal, exactly the maximum.
  EXPECT_TRUE(c.on_frame(0.0));
  EXPECT_TRUE(c.on_frame(-0.0));
  EXPECT_TRUE(c.on_frame(4.9e-324));
  EXPECT_TRUE(c.on_frame(C::kMaxFrameLatencyS));
  EXPECT_EQ(c.load_size_bytes(), 65000.0);  // an hour-long frame drops l to 0
  EXPECT_TRUE(std::isfinite(c.mip_bias()));
}

TEST(ControllerInput, ZerosKeepEverythingFinite) {
  stream::AdaptiveController c = make();
  for (int i = 0; i < 500; ++i) ASSERT_TRUE(c.on_frame(0.0));
  // t_w = 0 throughout: t_m = α/2 and x = -α/2, but Δl = P · Δt = 0, so l stays 0; the edges are all 0.
  EXPECT_EQ(c.state().t_w, 0.0);
  EXPECT_EQ(c.load_factor(), 0.0);
  EXPECT_EQ(c.mip_bias(), 0.0);  // degenerate edges
  EXPECT_EQ(c.load_size_bytes(), 65000.0);
}

TEST(ControllerModes, NoneAndFixed) {
  stream::ControllerParams none;
  none.mode = ControllerMode::kNone;
  stream::AdaptiveController n = make(none);
  for (double dt : {0.005, 0.5, 0.005}) {
    ASSERT_TRUE(n.on_frame(dt));
    EXPECT_EQ(n.load_size_bytes(), 64e6);
    EXPECT_EQ(n.mip_bias(), 0.0);
  }
  EXPECT_NEAR(n.weighted_latency_s(), C::weighted_latency(0.5, 0.005), 1e-15);  // t_w still tracked

  stream::ControllerParams fixed;
  fixed.mode = ControllerMode::kFixed;
  fixed.fixed_load_bytes = 2e6;
  fixed.fixed_bias = 1.5;
  stream::AdaptiveController f = make(fixed);
  ASSERT_TRUE(f.on_frame(0.2));
  EXPECT_EQ(f.load_size_bytes(), 2e6);
  EXPECT_EQ(f.load_bytes(), 2000000u);
  EXPECT_EQ(f.mip_bias(), 1.5);
}

TEST(ControllerParamsTest, FromConfigConvertsUnits) {
  ControllerConfig cfg;  // Table 2 defaults
  auto p = stream::ControllerParams::from_config(cfg);
  ASSERT_TRUE(p.ok()) << p.error().message;
  EXPECT_DOUBLE_EQ(p->alpha_s, 0.016);
  EXPECT_DOUBLE_EQ(p->s_min_bytes, 65000.0);
  EXPECT_DOUBLE_EQ(p->s_max_bytes, 64e6);
  EXPECT_EQ(p->mode, ControllerMode::kAuto);
  cfg.mode = ControllerMode::kNone;
  EXPECT_EQ(stream::ControllerParams::from_config(cfg)->mode, ControllerMode::kNone);
}

// An unknown controller.mode cannot reach from_config any more: the config parser refuses it naming the key
// (config_test.cpp, Config.AChoiceKeyTakesOnlyItsNames).
TEST(ControllerParamsTest, ErrorsNameTheKey) {
  ControllerConfig cfg;
  cfg.mode = ControllerMode::kFixed;
  cfg.fixed_load_mb = 100;  // above s_max = 64
  auto p = stream::ControllerParams::from_config(cfg);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().message.find("controller.fixed_load_mb"), std::string::npos);

  cfg = {};
  cfg.mode = ControllerMode::kFixed;
  cfg.fixed_bias = 9;  // above β = 8
  p = stream::ControllerParams::from_config(cfg);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().message.find("controller.fixed_bias"), std::string::npos);

  cfg = {};
  cfg.s_min_mb = 65;
  p = stream::ControllerParams::from_config(cfg);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.error().message.find("controller.s_min_mb"), std::string::npos);

  stream::ControllerParams bad;
  bad.alpha_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(C::create(bad).ok());
  bad = {};
  bad.beta = -1;
  EXPECT_FALSE(C::create(bad).ok());
}

}  // namespace
}  // namespace texstream
