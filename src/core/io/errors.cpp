#include "nursing_bed/core/io/errors.h"

namespace nursing_bed {

std::string ErrorList::text() const {
  std::string joined;
  for (std::size_t i = 0; i < errors_.size(); ++i) joined += (i ? "; " : "") + errors_[i];
  return joined;
}

}  // namespace nursing_bed
