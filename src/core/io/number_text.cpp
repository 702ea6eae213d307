#include "nursing_bed/core/io/number_text.h"

#include <charconv>
#include <cmath>

namespace nursing_bed {

bool parseFiniteNumber(std::string_view text, double* value) {
  const char* begin = text.data();
  const char* end = text.data() + text.size();
  if (begin != end && *begin == '+') ++begin;  // from_chars takes only '-'
  if (begin == end || *begin == '+' || (*begin == '-' && begin != text.data())) return false;
  double v = 0.0;
  const auto res = std::from_chars(begin, end, v);
  if (res.ec != std::errc() || res.ptr != end || !std::isfinite(v)) return false;
  *value = v;
  return true;
}

}  // namespace nursing_bed
