// A number as error messages in libs/estimation write it: all 17 significant digits, so the value
// refused is the value given (internal to the library's sources).
#pragma once

#include <sstream>
#include <string>

namespace rcal::estimation::detail {

inline std::string Num(double v) {
  std::ostringstream o;
  o.precision(17);
  o << v;
  return o.str();
}

}  // namespace rcal::estimation::detail
