// Reading a number typed by a user (a command-line value, a spec item) without the locale.
#pragma once

#include <string_view>

namespace nursing_bed {

/// The whole of `text` as a finite double: an optional leading '+' or '-', then what
/// std::from_chars reads. False, with *value untouched, for empty text, trailing characters,
/// an overflow, inf or nan.
bool parseFiniteNumber(std::string_view text, double* value);

}  // namespace nursing_bed
