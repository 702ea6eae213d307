// scripts/check_doc_links.py: every relative link of README.md and doc/*.md resolves; a broken
// link or anchor is named with its file.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;

namespace {

struct Result {
  int exit_code;
  std::string output;
};

Result checkLinks(const fs::path& root) {
  const std::string cmd = std::string("/usr/bin/python3 ") + NURSING_BED_SOURCE_DIR +
                          "/scripts/check_doc_links.py --root " + root.string() + " 2>&1";
  Result r{-1, ""};
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return r;
  char buf[512];
  while (fgets(buf, sizeof(buf), pipe)) r.output += buf;
  r.exit_code = pclose(pipe);
  return r;
}

void writeFile(const fs::path& p, const std::string& text) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << text;
}

fs::path smallTree(const std::string& name, const std::string& readme) {
  const fs::path root = fs::path(NURSING_BED_TEST_TMP_DIR) / ("links_" + name);
  fs::remove_all(root);
  writeFile(root / "README.md", readme);
  writeFile(root / "doc/a.md", "# Title\n\n## Some Section\n\nBack to [the readme](../README.md).\n");
  return root;
}

}  // namespace

TEST(DocLinks, EveryLinkOfThePackageResolves) {
  const Result r = checkLinks(NURSING_BED_SOURCE_DIR);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find(", 0 broken"), std::string::npos) << r.output;
}

TEST(DocLinks, GoodLinksAnchorsAndCodeSpansPass) {
  const Result r = checkLinks(smallTree(
      "good", "See [a](doc/a.md), [its section](doc/a.md#some-section), <https://example.org>, `[not](a/link.md)`.\n"));
  EXPECT_EQ(r.exit_code, 0) << r.output;
}

TEST(DocLinks, AMissingFileIsNamed) {
  const Result r = checkLinks(smallTree("missing", "See [b](doc/b.md).\n"));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("doc/b.md: no such file"), std::string::npos) << r.output;
}

TEST(DocLinks, AMissingAnchorIsNamed) {
  const Result r = checkLinks(smallTree("anchor", "See [a](doc/a.md#no-such-section).\n"));
  EXPECT_NE(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("no heading '#no-such-section'"), std::string::npos) << r.output;
}
