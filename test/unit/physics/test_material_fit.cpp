// Tests of the Yeoh least-squares fit (paper eq. 7-10) and the tensile CSV reader.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <random>
#include <stdexcept>
#include <string>

#include "nursing_bed/core/physics/material_fit.h"
#include "nursing_bed/core/physics/yeoh.h"

namespace nursing_bed {
namespace {

YeohMaterial yeoh(double c10_mpa, double c20_mpa, double c30_mpa) {
  YeohMaterial m;
  m.c10_pa = c10_mpa * 1e6;
  m.c20_pa = c20_mpa * 1e6;
  m.c30_pa = c30_mpa * 1e6;
  return m;
}

/// The generating constants of data/tpu_uniaxial.csv (scripts/make_tensile_data.py).
const YeohMaterial kTpu = yeoh(1.90, -0.35, 0.05);

/// 101 points, stretch 1 to 5, with relative Gaussian noise of sd `noise`.
TensileData syntheticCurve(const YeohMaterial& m, double noise, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  TensileData d;
  for (int i = 0; i <= 100; ++i) {
    const double l = 1.0 + 0.04 * i;
    d.stretch.push_back(l);
    d.stress_pa.push_back(m.uniaxialNominalStress(l) * (1.0 + noise * normal(rng)));
  }
  return d;
}

double relErr(double value, double truth) { return std::abs(value / truth - 1.0); }

double maxRelErr(const YeohMaterial& fit, const YeohMaterial& truth) {
  return std::max(
      {relErr(fit.c10_pa, truth.c10_pa), relErr(fit.c20_pa, truth.c20_pa), relErr(fit.c30_pa, truth.c30_pa)});
}

std::filesystem::path tmpDir() {
#ifdef NURSING_BED_TEST_TMP_DIR
  std::filesystem::path dir(NURSING_BED_TEST_TMP_DIR);
#else
  std::filesystem::path dir = std::filesystem::temp_directory_path() / "nursing_bed_test";
#endif
  std::filesystem::create_directories(dir);
  return dir;
}

std::string writeTemp(const std::string& name, const std::string& content) {
  const std::string path = (tmpDir() / ("material_fit_" + name + ".csv")).string();
  std::ofstream out(path, std::ios::binary);
  out << content;
  return path;
}

/// The message readTensileCsv throws for `content`, or "" if it does not throw.
std::string readError(const std::string& name, const std::string& content) {
  try {
    readTensileCsv(writeTemp(name, content));
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

void expectMentions(const std::string& message, std::initializer_list<const char*> parts) {
  EXPECT_FALSE(message.empty()) << "no error thrown";
  for (const char* part : parts)
    EXPECT_NE(message.find(part), std::string::npos) << "'" << part << "' not in: " << message;
}

const char* const kGoodRows = "1.0,0\n1.5,3.1e6\n2.0,3.6e6\n3.0,2.2e7\n4.0,1.5e8\n";

// ---------------------------------------------------------------------------------------------
// fitYeoh
// ---------------------------------------------------------------------------------------------

TEST(MaterialFit, ExactDataRecoveredToRounding) {
  for (FitWeighting w : {FitWeighting::kRelative, FitWeighting::kNone}) {
    YeohFitOptions options;
    options.weighting = w;
    const YeohFit fit = fitYeoh(syntheticCurve(kTpu, 0.0, 1), options);
    EXPECT_LT(maxRelErr(fit.material, kTpu), 1e-9);
    EXPECT_NEAR(fit.r_squared, 1.0, 1e-12);
    EXPECT_LT(fit.rms_residual_pa, 1e-3);
    EXPECT_EQ(fit.num_points, 101u);
    EXPECT_DOUBLE_EQ(fit.min_stretch, 1.0);
    EXPECT_DOUBLE_EQ(fit.max_stretch, 5.0);
    EXPECT_TRUE(fit.validation.empty()) << fit.validation;
  }
}

TEST(MaterialFit, RecoversConstantsFromNoisyData) {
  // 1 % noise; several seeds and a second material so one lucky draw cannot pass the test.
  for (const YeohMaterial& truth : {kTpu, yeoh(2.8, -0.6, 0.09)}) {
    for (unsigned seed : {1u, 2u, 3u}) {
      const YeohFit fit = fitYeoh(syntheticCurve(truth, 0.01, seed));
      SCOPED_TRACE("seed " + std::to_string(seed) + ", C10 " + std::to_string(truth.c10_pa));
      EXPECT_LT(relErr(fit.material.c10_pa, truth.c10_pa), 0.02);
      EXPECT_LT(relErr(fit.material.c20_pa, truth.c20_pa), 0.02);
      EXPECT_LT(relErr(fit.material.c30_pa, truth.c30_pa), 0.02);
      // The errors are consistent with the reported standard errors.
      EXPECT_LT(std::abs(fit.material.c10_pa - truth.c10_pa), 4.0 * fit.c10_stderr_pa);
      EXPECT_LT(std::abs(fit.material.c20_pa - truth.c20_pa), 4.0 * fit.c20_stderr_pa);
      EXPECT_LT(std::abs(fit.material.c30_pa - truth.c30_pa), 4.0 * fit.c30_stderr_pa);
      EXPECT_GT(fit.r_squared, 0.999);
      EXPECT_NEAR(fit.rms_relative_residual, 0.01, 0.003);
      EXPECT_TRUE(fit.validation.empty()) << fit.validation;
    }
  }
}

TEST(MaterialFit, WrongDataGivesDifferentConstants) {
  // Data from another C20: the fit follows the data, not the expected constants.
  YeohMaterial other = kTpu;
  other.c20_pa = -0.30e6;
  const YeohFit fit = fitYeoh(syntheticCurve(other, 0.01, 1));
  EXPECT_LT(relErr(fit.material.c20_pa, other.c20_pa), 0.02);
  EXPECT_GT(relErr(fit.material.c20_pa, kTpu.c20_pa), 0.10);

  // Stress 5 % high (e.g. a wrong cross-section): every constant 5 % high, outside 2 %.
  TensileData scaled = syntheticCurve(kTpu, 0.01, 1);
  for (double& s : scaled.stress_pa) s *= 1.05;
  const YeohFit fit_scaled = fitYeoh(scaled);
  EXPECT_GT(relErr(fit_scaled.material.c10_pa, kTpu.c10_pa), 0.02);
  EXPECT_GT(relErr(fit_scaled.material.c20_pa, kTpu.c20_pa), 0.02);
  EXPECT_GT(relErr(fit_scaled.material.c30_pa, kTpu.c30_pa), 0.02);
}

TEST(MaterialFit, StandardErrorsMatchTheScatterOfRepeatedFits) {
  constexpr int kRuns = 200;
  double sum[3] = {0, 0, 0}, sum_sq[3] = {0, 0, 0}, stderr_sum[3] = {0, 0, 0};
  for (int run = 0; run < kRuns; ++run) {
    const YeohFit fit = fitYeoh(syntheticCurve(kTpu, 0.01, 100u + static_cast<unsigned>(run)));
    const double c[3] = {fit.material.c10_pa, fit.material.c20_pa, fit.material.c30_pa};
    const double se[3] = {fit.c10_stderr_pa, fit.c20_stderr_pa, fit.c30_stderr_pa};
    for (int k = 0; k < 3; ++k) {
      sum[k] += c[k];
      sum_sq[k] += c[k] * c[k];
      stderr_sum[k] += se[k];
    }
  }
  for (int k = 0; k < 3; ++k) {
    const double mean = sum[k] / kRuns;
    const double sd = std::sqrt((sum_sq[k] - kRuns * mean * mean) / (kRuns - 1));
    const double mean_stderr = stderr_sum[k] / kRuns;
    EXPECT_GT(mean_stderr, 0.7 * sd) << "constant " << k;
    EXPECT_LT(mean_stderr, 1.4 * sd) << "constant " << k;
  }
}

TEST(MaterialFit, UnderdeterminedDataThrows) {
  TensileData at_rest;
  at_rest.stretch = {1.0, 1.0, 1.0, 1.0};
  at_rest.stress_pa = {0.0, 0.0, 0.0, 0.0};
  EXPECT_THROW(fitYeoh(at_rest), std::invalid_argument);

  TensileData two_stretches;
  two_stretches.stretch = {1.5, 2.0, 1.5, 2.0, 1.5};
  two_stretches.stress_pa = {3e6, 4e6, 3e6, 4e6, 3e6};
  EXPECT_THROW(fitYeoh(two_stretches), std::invalid_argument);

  TensileData mismatched = syntheticCurve(kTpu, 0.0, 1);
  mismatched.stress_pa.pop_back();
  EXPECT_THROW(fitYeoh(mismatched), std::invalid_argument);
}

TEST(MaterialFit, ShippedTpuDataFits) {
  const std::string path = NURSING_BED_SOURCE_DIR "/data/tpu_uniaxial.csv";
  const TensileData data = readTensileCsv(path);
  EXPECT_GE(data.stretch.size(), 80u);
  const YeohFit fit = fitYeoh(data);
  EXPECT_GT(fit.r_squared, 0.99);
  EXPECT_LT(relErr(fit.material.c10_pa, kTpu.c10_pa), 0.05);
  EXPECT_LT(relErr(fit.material.c20_pa, kTpu.c20_pa), 0.05);
  EXPECT_LT(relErr(fit.material.c30_pa, kTpu.c30_pa), 0.05);
  EXPECT_TRUE(fit.validation.empty()) << fit.validation;

  // The file says it is synthetic.
  std::ifstream in(path);
  std::string first_line;
  std::getline(in, first_line);
  EXPECT_NE(first_line.find("SYNTHETIC"), std::string::npos) << first_line;
}

// ---------------------------------------------------------------------------------------------
// readTensileCsv
// ---------------------------------------------------------------------------------------------

TEST(TensileCsv, ReadsCommentsExtraColumnsAnyOrderAndCrlf) {
  const std::string path = writeTemp("good",
                                     "# synthetic\r\n#  more\r\n\r\ntime_s, Stress_Pa ,force_n,stretch\r\n"
                                     "0,0,0,1.0\r\n1,3.1e6,5,1.5\r\n2,3.6e6,6,2.0\r\n3,2.2e7,7,3.0\r\n");
  const TensileData d = readTensileCsv(path);
  ASSERT_EQ(d.stretch.size(), 4u);
  EXPECT_DOUBLE_EQ(d.stretch[1], 1.5);
  EXPECT_DOUBLE_EQ(d.stress_pa[1], 3.1e6);
  EXPECT_DOUBLE_EQ(d.stretch[3], 3.0);
  EXPECT_EQ(d.source, path);
}

TEST(TensileCsv, StrainColumnAccepted) {
  const TensileData d = readTensileCsv(writeTemp("strain", "strain,stress_pa\n0,0\n0.5,3.1e6\n1.0,3.6e6\n2.0,2.2e7\n"));
  ASSERT_EQ(d.stretch.size(), 4u);
  EXPECT_DOUBLE_EQ(d.stretch[0], 1.0);
  EXPECT_DOUBLE_EQ(d.stretch[1], 1.5);
  EXPECT_DOUBLE_EQ(d.stretch[3], 3.0);
}

TEST(TensileCsv, MpaColumnAccepted) {
  const TensileData d = readTensileCsv(writeTemp("mpa", "stress_mpa,stretch\n0,1.0\n3.1,1.5\n3.6,2.0\n22,3.0\n"));
  ASSERT_EQ(d.stress_pa.size(), 4u);
  EXPECT_DOUBLE_EQ(d.stress_pa[1], 3.1e6);
  EXPECT_DOUBLE_EQ(d.stress_pa[3], 22e6);
  EXPECT_DOUBLE_EQ(d.stretch[2], 2.0);
}

TEST(TensileCsv, MissingColumnNamed) {
  expectMentions(readError("no_stress", std::string("# c\nstretch,force_n\n") + kGoodRows),
                 {"material_fit_no_stress.csv:2", "stress_pa", "stress_mpa", "force_n"});
  expectMentions(readError("no_stretch", "displacement_m,stress_pa\n0,0\n"),
                 {"material_fit_no_stretch.csv:1", "'stretch'", "'strain'"});
}

TEST(TensileCsv, NonNumericFieldNamedWithLine) {
  const std::string msg =
      readError("non_numeric", "# comment\nstretch,stress_pa\n1.0,0\n1.5,3.1e6\n2.0,3.6x6\n3.0,2.2e7\n");
  expectMentions(msg, {"material_fit_non_numeric.csv:5", "'stress_pa'", "'3.6x6'"});
  expectMentions(readError("empty_field", "stretch,stress_pa,note\n1.0,0,a\n1.5,,b\n"),
                 {"material_fit_empty_field.csv:3", "'stress_pa'", "not a finite number"});
  expectMentions(readError("nan_field", "stretch,stress_pa\n1.0,0\nnan,1e6\n"),
                 {"material_fit_nan_field.csv:3", "'stretch'", "'nan'"});
}

TEST(TensileCsv, TooFewRows) {
  expectMentions(readError("few", "stretch,stress_pa\n1.0,0\n1.5,3.1e6\n2.0,3.6e6\n"),
                 {"material_fit_few.csv", "3 data rows", "at least 4"});
  expectMentions(readError("header_only", "# nothing\nstretch,stress_pa\n"),
                 {"material_fit_header_only.csv", "0 data rows"});
  expectMentions(readError("empty", "# only comments\n"), {"material_fit_empty.csv", "no header"});
}

TEST(TensileCsv, StretchRules) {
  expectMentions(readError("neg_stretch", "strain,stress_pa\n0,0\n-1.0,1\n0.5,3e6\n1,4e6\n"),
                 {"material_fit_neg_stretch.csv:3", "'strain'", "stretch must be > 0"});
  expectMentions(readError("compression", "stretch,stress_pa\n1.0,0\n0.9,-1e6\n0.8,-2e6\n0.7,-3e6\n"),
                 {"material_fit_compression.csv", "no stretch > 1"});
}

TEST(TensileCsv, MalformedFileNamed) {
  expectMentions(readError("field_count", "stretch,stress_pa\n1.0,0\n1.5,3.1e6,7\n"),
                 {"material_fit_field_count.csv:3", "3 fields", "header has 2"});
  expectMentions(readError("both", std::string("stretch,strain,stress_pa\n") + kGoodRows),
                 {"material_fit_both.csv:1", "'stretch'", "'strain'"});
  expectMentions(readError("twice", std::string("stretch,stress_pa,stress_pa\n") + kGoodRows),
                 {"material_fit_twice.csv:1", "'stress_pa' appears twice"});
  const std::string missing = (tmpDir() / "material_fit_does_not_exist.csv").string();
  std::filesystem::remove(missing);
  try {
    readTensileCsv(missing);
    ADD_FAILURE() << "no error for a missing file";
  } catch (const std::runtime_error& e) {
    expectMentions(e.what(), {"material_fit_does_not_exist.csv", "cannot open"});
  }
}

}  // namespace
}  // namespace nursing_bed
