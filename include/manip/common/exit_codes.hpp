#pragma once
// One exit-code table for every manip program (docs/exit-codes.md; each
// --help prints the rows that apply to it). sysexits-style numbers are not
// used because the lab's scripts test these by value: they are part of the
// interface and never renumbered.
namespace manip::exit_code {

inline constexpr int kOk = 0;             // success
inline constexpr int kPartial = 1;        // results written, but inputs were excluded or results flagged (reasons printed)
inline constexpr int kUsage = 2;          // bad command line (option, value out of range)
inline constexpr int kConfig = 3;         // configuration file invalid or unreadable (file:line: key: reason)
inline constexpr int kInput = 4;          // an input file unusable: missing, not an LCM log, no/invalid session message
inline constexpr int kNothing = 5;        // nothing to compute: no usable perturbed trial in any input
inline constexpr int kOutput = 6;         // output cannot be written: exists (no --force), in use, disk full
inline constexpr int kFault = 7;          // manip_rt: the session ended by (or with) a latched safety fault
inline constexpr int kBackend = 8;        // manip_rt: hardware backend unavailable or failed to start
inline constexpr int kRealtime = 9;       // manip_rt: --require-rt and real-time set-up failed
inline constexpr int kBus = 10;           // LCM bus cannot be created with the given URL
inline constexpr int kInternal = 70;      // unexpected internal error (a bug: please report it)
inline constexpr int kInterrupted = 130;  // stopped by a signal (SIGINT/SIGTERM/SIGHUP); safe stop done, outputs closed

// "3 (configuration invalid)" style names for messages and tests.
const char* name(int code);

}  // namespace manip::exit_code
