// Numbers as text (lidef/number_format.h): a bound printed with few digits is still a bound.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <random>

#include "lidef/number_format.h"

using namespace lidef;

TEST(NumberFormat, BoundsAreRoundedAwayFromWhatTheyBound) {
  EXPECT_EQ(format_bound(1.31349, true, 4), "1.314");
  EXPECT_EQ(format_bound(1.31349, false, 4), "1.313");
  EXPECT_EQ(format_bound(1.31351, false, 4), "1.313");
  EXPECT_EQ(format_bound(0.85, false, 4), "0.85");  // exact at that precision: unchanged
  EXPECT_EQ(format_bound(9.99951, true, 4), "10");  // the carry into the next decade
  EXPECT_EQ(format_bound(-2.00049, true, 4), "-2");
  EXPECT_EQ(format_bound(std::numeric_limits<double>::infinity(), true, 4), "inf");
  // Random numbers of every scale: the printed number reads back on the right side, within two units of the
  // last digit.
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> mant(-10, 10);
  std::uniform_int_distribution<int> ex(-12, 12);
  for (int k = 0; k < 20000; ++k) {
    const double x = mant(rng) * std::pow(10.0, ex(rng));
    for (const bool upper : {true, false}) {
      const std::string s = format_bound(x, upper, 4);
      const double v = std::strtod(s.c_str(), nullptr);
      if (upper)
        ASSERT_GE(v, x) << s;
      else
        ASSERT_LE(v, x) << s;
      ASSERT_LE(std::abs(v - x), 2e-3 * std::abs(x) + 1e-300) << s;
    }
  }
}
