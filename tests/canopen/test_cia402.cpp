#include <catch2/catch.hpp>

#include "manip/canopen/cia402.hpp"

using namespace manip::canopen::cia402;

TEST_CASE("cia402: statusword decoding with the masks of CiA 402 (0x4F / 0x6F)") {
  CHECK(decode(0x0000) == State::NotReadyToSwitchOn);
  CHECK(decode(0x0250) == State::SwitchOnDisabled);  // + remote + voltage bits
  CHECK(decode(0x0021) == State::ReadyToSwitchOn);
  CHECK(decode(0x0233) == State::SwitchedOn);
  CHECK(decode(0x0637) == State::OperationEnabled);
  CHECK(decode(0x0007) == State::QuickStopActive);
  CHECK(decode(0x001F) == State::FaultReactionActive);
  CHECK(decode(0x0218) == State::Fault);
  for (State s : {State::SwitchOnDisabled, State::ReadyToSwitchOn, State::SwitchedOn, State::OperationEnabled,
                  State::QuickStopActive, State::FaultReactionActive, State::Fault})
    CHECK(decode(encode(s)) == s);
}

TEST_CASE("cia402: enable path 2, 3, 4 with the controlwords of the standard - disable 9") {
  CHECK(master_step(0x0040, Target::OperationEnabled, false, 0).controlword == 0x06);
  CHECK(master_step(0x0040, Target::OperationEnabled, false, 0).transition == 2);
  CHECK(master_step(0x0021, Target::OperationEnabled, false, 0x06).controlword == 0x07);
  CHECK(master_step(0x0021, Target::OperationEnabled, false, 0x06).transition == 3);
  CHECK(master_step(0x0023, Target::OperationEnabled, false, 0x07).controlword == 0x0F);
  CHECK(master_step(0x0023, Target::OperationEnabled, false, 0x07).transition == 4);
  CHECK(master_step(0x0027, Target::OperationEnabled, false, 0x0F).controlword == 0x0F);
  CHECK(master_step(0x0027, Target::Disabled, false, 0x0F).controlword == 0x00);
  CHECK(master_step(0x0027, Target::Disabled, false, 0x0F).transition == 9);
  CHECK(master_step(0x0027, Target::QuickStop, false, 0x0F).controlword == 0x02);
  CHECK(master_step(0x0027, Target::QuickStop, false, 0x0F).transition == 11);

  // Closed loop with the drive side from Not ready: transitions 1, 2, 3, 4.
  State s = State::NotReadyToSwitchOn;
  uint16_t prev = 0;
  std::vector<int> seen;
  for (int i = 0; i < 6 && s != State::OperationEnabled; ++i) {
    const auto m = master_step(encode(s), Target::OperationEnabled, false, prev);
    const auto d = drive_step(s, m.controlword, prev, false);
    prev = m.controlword;
    s = d.state;
    seen.push_back(d.transition);
  }
  CHECK(s == State::OperationEnabled);
  CHECK(seen == std::vector<int>{1, 2, 3, 4});
}

TEST_CASE("cia402: fault reset only on request and only as a rising edge of bit 7 (transition 15)") {
  for (uint16_t prev : {0x0000, 0x0080, 0x000F, 0x0006})
    for (Target t : {Target::Disabled, Target::OperationEnabled}) {
      const auto m = master_step(0x0008, t, false, prev);
      CHECK((m.controlword & 0x80) == 0);
      CHECK(m.transition == -1);
    }
  CHECK(master_step(0x0008, Target::Disabled, true, 0x0000).controlword == 0x80);
  CHECK(master_step(0x0008, Target::Disabled, true, 0x0000).transition == 15);
  CHECK(master_step(0x0008, Target::Disabled, true, 0x0080).controlword == 0x00);  // low first, then the edge

  // Drive side: a held bit 7 does not reset, a rising edge does.
  CHECK(drive_step(State::Fault, 0x80, 0x80, false).state == State::Fault);
  CHECK(drive_step(State::Fault, 0x80, 0x00, false).state == State::SwitchOnDisabled);
  CHECK(drive_step(State::Fault, 0x80, 0x00, false).transition == 15);
  // Fault condition from any state: 13 then 14.
  CHECK(drive_step(State::OperationEnabled, 0x0F, 0x0F, true).transition == 13);
  CHECK(drive_step(State::FaultReactionActive, 0x0F, 0x0F, true).transition == 14);
  // Master + drive from Fault with a reset request that arrives while bit 7 is high.
  State s = State::Fault;
  uint16_t prev = 0x80;
  std::vector<uint16_t> cws;
  for (int i = 0; i < 3 && s == State::Fault; ++i) {
    const auto m = master_step(encode(s), Target::Disabled, true, prev);
    s = drive_step(s, m.controlword, prev, false).state;
    prev = m.controlword;
    cws.push_back(m.controlword);
  }
  CHECK(cws == std::vector<uint16_t>{0x00, 0x80});
  CHECK(s == State::SwitchOnDisabled);
}
