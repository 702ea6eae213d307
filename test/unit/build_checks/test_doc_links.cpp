// scripts/check_doc_links.py: every relative link of README.md and doc/*.md resolves; a broken
// link or anchor is named with its file.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult checkLinks(const fs::path& root) {
  return runCommand("/usr/bin/python3 " + shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/check_doc_links.py") +
                    " --root " + shellQuote(root.string()));
}

fs::path smallTree(const std::string& name, const std::string& readme) {
  const fs::path root = freshTestDir("links", name);
  fs::create_directories(root / "doc");
  writeFile(root / "README.md", readme);
  writeFile(root / "doc/a.md", "# Title\n\n## Some Section\n\nBack to [the readme](../README.md).\n");
  return root;
}

}  // namespace

TEST(DocLinks, EveryLinkOfThePackageResolves) {
  const ToolResult r = checkLinks(NURSING_BED_SOURCE_DIR);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find(", 0 broken"), std::string::npos) << r.output;
}

TEST(DocLinks, GoodLinksAnchorsAndCodeSpansPass) {
  const ToolResult r = checkLinks(smallTree(
      "good", "See [a](doc/a.md), [its section](doc/a.md#some-section), <https://example.org>, `[not](a/link.md)`.\n"));
  EXPECT_EQ(r.code, 0) << r.output;
}

TEST(DocLinks, AMissingFileIsNamed) {
  const ToolResult r = checkLinks(smallTree("missing", "See [b](doc/b.md).\n"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("doc/b.md: no such file"), std::string::npos) << r.output;
}

TEST(DocLinks, AMissingAnchorIsNamed) {
  const ToolResult r = checkLinks(smallTree("anchor", "See [a](doc/a.md#no-such-section).\n"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_NE(r.output.find("no heading '#no-such-section'"), std::string::npos) << r.output;
}
