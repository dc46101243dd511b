// Bus budgets computed by hand from the frame formula
// 47 + 8n bits + floor((34 + 8n - 1) / 4) stuff bits.
#include <catch2/catch.hpp>

#include "manip/canopen/bus_load.hpp"
#include "manip/canopen/master.hpp"
#include "rig.hpp"

using namespace manip::canopen;

TEST_CASE("canopen bus load: frame lengths by hand") {
  CHECK(frame_bits_worst(0) == 47 + 8);        // SYNC: floor(33/4) = 8
  CHECK(frame_bits_worst(1) == 55 + 10);       // heartbeat: floor(41/4) = 10
  CHECK(frame_bits_worst(4) == 79 + 16);       // RPDO cw + torque: floor(65/4) = 16
  CHECK(frame_bits_worst(6) == 95 + 20);       // TPDO sw + position: floor(81/4) = 20
  CHECK(frame_bits_worst(8) == 111 + 24);      // EMCY: floor(97/4) = 24
}

TEST_CASE("canopen bus load: shared bus at 2 kHz is refused, at 1 kHz accepted") {
  auto cfg = canopen_test::parse_ok(canopen_test::kSharedBus);
  cfg.master.sync_period_us = 500;
  auto b = compute_budgets(cfg);
  REQUIRE(b.size() == 1);
  // per SYNC: 55 + 2 * 95 + 2 * 115 = 475 bits, 2000 per s
  CHECK(b[0].cyclic_bits_per_sync == 475);
  // heartbeats: drives 2 * 20 Hz * 65, master 50 Hz * 65; EMCY 2 * 10 Hz * 135
  const double hand = 475.0 * 2000 + 2 * 20 * 65 + 50 * 65 + 2 * 10 * 135;  // 958550
  CHECK(b[0].bits_per_s == Approx(hand));
  CHECK(b[0].load == Approx(0.95855));
  CHECK_FALSE(b[0].ok());
  CHECK(b[0].table().find("REFUSED") != std::string::npos);

  cfg.master.sync_period_us = 1000;
  b = compute_budgets(cfg);
  CHECK(b[0].bits_per_s == Approx(475.0 * 1000 + 2600 + 3250 + 2700));  // 48.4 %
  CHECK(b[0].ok());
}

TEST_CASE("canopen bus load: one bus per drive at 2 kHz, velocity TPDO2 does not fit") {
  auto cfg = canopen_test::parse_ok(canopen_test::kTwoBuses);
  auto b = compute_budgets(cfg);
  REQUIRE(b.size() == 2);
  for (const auto& x : b) {
    CHECK(x.cyclic_bits_per_sync == 55 + 95 + 115);
    CHECK(x.bits_per_s == Approx(265.0 * 2000 + 20 * 65 + 50 * 65 + 10 * 135));  // 535900
    CHECK(x.load == Approx(0.5359));
    CHECK(x.ok());
  }
  for (auto& d : cfg.drives) d.tpdo2.add(PdoObject::VelocityActual);
  b = compute_budgets(cfg);
  // + TPDO2 with 4 bytes (95 bits) per SYNC -> 360 bits * 2000 + 5900 = 725900
  CHECK(b[0].bits_per_s == Approx(725900.0));
  CHECK_FALSE(b[0].ok());
}

TEST_CASE("canopen bus load: 0x60FD digital inputs in TPDO2 are in the budget") {
  auto cfg = canopen_test::parse_ok(canopen_test::kTwoBuses);
  cfg.master.max_bus_load = 0.75;
  // instead of the velocity: TPDO2 = 0x60FD (4 bytes, 95 bits) -> as with velocity, 72.6 %
  for (auto& d : cfg.drives) d.tpdo2.add(PdoObject::DigitalInputs);
  auto b = compute_budgets(cfg);
  CHECK(b[0].cyclic_bits_per_sync == 55 + 95 + 115 + 95);
  CHECK(b[0].bits_per_s == Approx(360.0 * 2000 + 20 * 65 + 50 * 65 + 10 * 135));  // 725900
  CHECK(b[0].ok());
  CHECK(b[0].table().find("TPDO2") != std::string::npos);
  // velocity and 0x60FD: TPDO2 8 bytes (135 bits) -> 400 bits per SYNC, 80.6 %: refused at 75 %
  for (auto& d : cfg.drives) d.tpdo2.add(PdoObject::VelocityActual);
  b = compute_budgets(cfg);
  CHECK(b[0].cyclic_bits_per_sync == 55 + 95 + 115 + 135);
  CHECK(b[0].bits_per_s == Approx(400.0 * 2000 + 5900));  // 805900
  CHECK_FALSE(b[0].ok());
}

TEST_CASE("canopen bus load: the master refuses to start an over-budget bus, before sending anything") {
  auto cfg = canopen_test::parse_ok(canopen_test::kSharedBus);
  cfg.master.sync_period_us = 500;
  Master m(cfg, "can");
  m.start(0);
  FrameBuffer tx;
  m.process(250, {}, tx);
  CHECK(m.phase() == Phase::Failed);
  CHECK(m.error().code == ErrorCode::BusLoadTooHigh);
  CHECK(tx.empty());
  CHECK(describe(m.error()) == "bus: worst-case bus load above the limit (95.9 % > limit 70.0 %)");
}
