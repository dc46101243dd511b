// Harness (b): arbitrary bytes as an LCM log file, through the event-log
// reader, the session stream (safe_decode of every payload) and the trial
// assembler, i.e. what `estimate_impedance file.lcm` does before estimating.
//
// manip-fuzz-sources: src/logging/*.cpp src/estimation/trial_data.cpp src/model/*.cpp src/common/*.cpp
//
// Findings: any crash, sanitizer report, leak or timeout; any exception other
// than std::runtime_error (the documented way to refuse a file); and a broken
// reader invariant (checked below, aborts):
//  - accepted events, skipped regions and the truncated tail tile the file
//    exactly (every byte is accounted for, nothing read twice);
//  - the read buffer never exceeds min(file size, max(kMinBufferBytes,
//    largest accepted event + kReadAheadBytes)) (the bound of event_log.hpp).
#include <sys/mman.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "manip/estimation/trial_data.hpp"
#include "manip/logging/event_log.hpp"
#include "manip/logging/session_stream.hpp"

namespace {

// The reader takes a path: an in-memory file, rewritten for every input.
const std::string& input_path() {
  static const std::string path = [] {
    const int fd = memfd_create("manip_fuzz_log", 0);
    if (fd < 0) {
      std::perror("memfd_create");
      std::abort();
    }
    return "/proc/self/fd/" + std::to_string(fd);
  }();
  return path;
}

void write_input(const std::uint8_t* data, std::size_t size) {
  std::FILE* f = std::fopen(input_path().c_str(), "wb");  // truncates
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
}

void check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "invariant broken: %s\n", what);
    std::abort();
  }
}

void reader_invariants() {
  using manip::logging::EventLogReader;
  try {
    EventLogReader r(input_path());
    manip::logging::RawEvent ev;
    std::uint64_t covered = 0, expect_at = 0;
    std::size_t skip_i = 0;
    const auto& d = r.diagnostics();
    while (r.next(ev)) {
      // Skipped regions reported so far lie before this event, in order.
      for (; skip_i < d.skipped.size(); ++skip_i) {
        check(d.skipped[skip_i].offset == expect_at, "skipped region starts where the last event/region ended");
        expect_at += d.skipped[skip_i].bytes;
      }
      check(ev.offset == expect_at, "event starts where the last event/region ended");
      const std::uint64_t total = manip::logging::kEventHeaderBytes + ev.channel.size() + ev.data.size();
      expect_at += total;
      covered += total;
    }
    for (; skip_i < d.skipped.size(); ++skip_i) {
      check(d.skipped[skip_i].offset == expect_at, "trailing skipped region in order");
      expect_at += d.skipped[skip_i].bytes;
    }
    covered += d.bytes_skipped;
    if (d.truncated_tail) {
      check(d.truncated_offset == expect_at, "truncated tail right after the last region");
      covered += r.file_size() - d.truncated_offset;
    }
    check(covered == r.file_size(), "events + skipped + truncated tail == file size");
    const std::size_t bound = std::min<std::size_t>(
        r.file_size(), std::max<std::size_t>(EventLogReader::kMinBufferBytes,
                                             d.largest_event_bytes + EventLogReader::kReadAheadBytes));
    check(r.buffer_bytes() <= bound, "read buffer within the documented allocation bound");
  } catch (const std::runtime_error&) {
    // Not an LCM log at all (no magic at byte 0): refused, as documented.
  }
}

void assemble() {
  std::size_t samples = 0;
  manip::estimation::TrialAssembler asmb([&](const manip::estimation::SessionInfo&, manip::estimation::TrialData&& t) {
    samples += t.size();
  });
  asmb.set_keep_unperturbed_signals(false);
  try {
    manip::logging::read_log(input_path(), asmb);
    asmb.finish();
  } catch (const std::runtime_error&) {
    // Refused logs (not LCM, unknown schema version, no session message, ...).
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  write_input(data, size);
  reader_invariants();
  assemble();
  return 0;
}
