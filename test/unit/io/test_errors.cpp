// ErrorList (the problems of a validate() joined with "; ") and Status (success or a message).
#include <gtest/gtest.h>

#include "nursing_bed/core/io/errors.h"
#include "nursing_bed/core/io/status.h"

namespace nb = nursing_bed;

TEST(Status, SuccessIsOkWithoutAMessage) {
  const nb::Status s = nb::Status::success();
  EXPECT_TRUE(s.ok());
  EXPECT_TRUE(static_cast<bool>(s));
  EXPECT_EQ(s.message(), "");
}

TEST(Status, AnErrorIsNotOkAndKeepsItsMessage) {
  const nb::Status s = nb::Status::error("chambers must be 1..8, got 9");
  EXPECT_FALSE(s.ok());
  EXPECT_FALSE(static_cast<bool>(s));
  EXPECT_EQ(s.message(), "chambers must be 1..8, got 9");
  EXPECT_FALSE(nb::Status::error("").ok());  // an empty message still fails
}

TEST(ErrorList, AnEmptyListIsOkWithEmptyText) {
  const nb::ErrorList errors;
  EXPECT_TRUE(errors.ok());
  EXPECT_EQ(errors.text(), "");
  EXPECT_TRUE(errors.status().ok());
}

TEST(ErrorList, JoinsTheProblemsWithSemicolonsAndNoTrailingSeparator) {
  nb::ErrorList errors;
  errors.add("no terminals");
  errors.add("port ", 70000, " not in 1..65535");
  EXPECT_FALSE(errors.ok());
  EXPECT_EQ(errors.text(), "no terminals; port 70000 not in 1..65535");
  const nb::Status s = errors.status();
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.message(), errors.text());
}

TEST(ErrorList, StreamsNumbersAsAnOstreamDoes) {
  nb::ErrorList errors;
  const double value = 1.0 / 3.0;
  errors.add("face_side_m must be a positive finite number, got ", value);
  std::ostringstream expected;
  expected << "face_side_m must be a positive finite number, got " << value;
  EXPECT_EQ(errors.text(), expected.str());
}

TEST(ErrorList, AddIfAddsOnlyWhenTheConditionIsBad) {
  nb::ErrorList errors;
  errors.addIf(false, "not added");
  EXPECT_TRUE(errors.ok());
  errors.addIf(true, "bed_cells must be >= 0");
  EXPECT_EQ(errors.text(), "bed_cells must be >= 0");
}

TEST(ErrorList, NestedChecksArePrefixedAndSkippedWhenTheyPass) {
  nb::ErrorList errors;
  errors.addNested(nb::Status::success(), "material: ");
  errors.addNested(std::string(), "observer/: ");
  EXPECT_TRUE(errors.ok());
  errors.addNested(nb::Status::error("c10_pa must be positive"), "material: ");
  errors.addNested(std::string("gain must be positive"), "observer/: ");
  errors.addNested(std::string("hardware/plugin is empty"));
  EXPECT_EQ(errors.text(),
            "material: c10_pa must be positive; observer/: gain must be positive; hardware/plugin is empty");
}
