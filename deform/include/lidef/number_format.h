// Numbers as text: the one formatter of lidef's files and messages.
#pragma once
#include <string>

namespace lidef {

// The shortest text that reads back as exactly `x` (std::to_chars): coefficient files, OBJ, JSON-like
// outputs.
std::string format_double(double x);

// printf's "%.<digits>g": messages, tables and labels ("0.0123", "1.5e+06"); "nan", "inf" as printf writes
// them.
std::string format_g(double x, int digits = 6);

// printf's "%.<decimals>f": durations and percentages ("0.12").
std::string format_fixed(double x, int decimals);

}  // namespace lidef
