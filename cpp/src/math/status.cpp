#include "wmo/types.h"

namespace wmo {

const char* to_string(QueryStatus s) {
  switch (s) {
    case QueryStatus::kOk: return "ok";
    case QueryStatus::kUnsupported: return "unsupported";
    case QueryStatus::kMaxIterations: return "max_iterations";
    case QueryStatus::kDegenerate: return "degenerate";
  }
  return "unknown";
}

}  // namespace wmo
