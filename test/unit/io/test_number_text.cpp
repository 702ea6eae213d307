#include <gtest/gtest.h>

#include "nursing_bed/core/io/number_text.h"

namespace nursing_bed {
namespace {

TEST(NumberText, ReadsSignedDecimalAndExponentForms) {
  double v = 0.0;
  ASSERT_TRUE(parseFiniteNumber("+0.05", &v));
  EXPECT_DOUBLE_EQ(v, 0.05);
  ASSERT_TRUE(parseFiniteNumber("-4.1e-2", &v));
  EXPECT_DOUBLE_EQ(v, -0.041);
  ASSERT_TRUE(parseFiniteNumber("300", &v));
  EXPECT_DOUBLE_EQ(v, 300.0);
}

TEST(NumberText, RefusesWhatIsNotOneFiniteNumberAndLeavesTheValue) {
  for (const char* bad : {"", "+", "++1", "+-1", "1.5x", " 1", "1e999", "inf", "nan", "0x10", "1,5"}) {
    double v = 7.0;
    EXPECT_FALSE(parseFiniteNumber(bad, &v)) << "'" << bad << "'";
    EXPECT_EQ(v, 7.0) << "'" << bad << "'";
  }
}

}  // namespace
}  // namespace nursing_bed
