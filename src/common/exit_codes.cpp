#include "manip/common/exit_codes.hpp"

namespace manip::exit_code {

const char* name(int code) {
  switch (code) {
    case kOk: return "ok";
    case kPartial: return "partial (inputs excluded or results flagged)";
    case kUsage: return "usage error";
    case kConfig: return "configuration invalid";
    case kInput: return "input unusable";
    case kNothing: return "nothing to compute";
    case kOutput: return "output cannot be written";
    case kFault: return "safety fault";
    case kBackend: return "backend unavailable";
    case kRealtime: return "real-time set-up failed";
    case kBus: return "LCM bus unavailable";
    case kInternal: return "internal error";
    case kInterrupted: return "interrupted (stopped safely)";
    default: return "unknown";
  }
}

}  // namespace manip::exit_code
