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

// format_g for a number that is a bound: the `digits`-digit text rounded away from what it bounds (up for an
// upper bound, down for a lower one), so that the printed number is a bound too ("sigma1 <= 1.314" for
// 1.31349). Non-finite numbers as format_g writes them.
std::string format_bound(double x, bool upper, int digits = 6);

// printf's "%.<decimals>f": durations and percentages ("0.12").
std::string format_fixed(double x, int decimals);

}  // namespace lidef
