// Small helpers shared by the gtest files (unit and unit_ros).
#pragma once

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace nursing_bed {
namespace test {

/// An empty scratch directory <tmp>/<group>/<name> (under the build's test_tmp when defined).
inline std::filesystem::path freshTestDir(const std::string& group, const std::string& name, bool create = true) {
#ifdef NURSING_BED_TEST_TMP_DIR
  std::filesystem::path dir = std::filesystem::path(NURSING_BED_TEST_TMP_DIR) / group / name;
#else
  std::filesystem::path dir = std::filesystem::temp_directory_path() / ("nursing_bed_" + group) / name;
#endif
  std::filesystem::remove_all(dir);
  if (create) std::filesystem::create_directories(dir);
  return dir;
}

/// Writes `text` to `path`; returns the path.
inline std::string writeFile(const std::filesystem::path& path, const std::string& text) {
  std::ofstream(path) << text;
  return path.string();
}

/// The whole file (empty when it cannot be read).
inline std::string slurp(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

/// Expects an error message that contains every fragment.
inline void expectContains(const std::string& message, const std::vector<std::string>& fragments) {
  EXPECT_FALSE(message.empty()) << "no error";
  for (const auto& f : fragments) EXPECT_NE(message.find(f), std::string::npos) << "'" << f << "' not in: " << message;
}

/// A shell word: `s` in single quotes.
inline std::string shellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

struct ToolResult {
  int code = -1;       ///< exit code (-1: did not exit normally)
  std::string output;  ///< stdout and stderr together
};

/// Runs a shell command, capturing stdout and stderr together.
inline ToolResult runCommand(const std::string& command) {
  ToolResult r;
  FILE* pipe = ::popen((command + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  std::size_t n = 0;
  while ((n = std::fread(buf, 1, sizeof(buf), pipe)) > 0) r.output.append(buf, n);
  const int status = ::pclose(pipe);
  if (status != -1 && WIFEXITED(status)) r.code = WEXITSTATUS(status);
  return r;
}

}  // namespace test
}  // namespace nursing_bed
