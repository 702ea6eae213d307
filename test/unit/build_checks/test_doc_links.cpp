// scripts/check_doc_links.py: every relative link of README.md and doc/*.md resolves, every doc
// page a code comment names exists, and nothing names a file outside the repository; a broken
// link or anchor is named with its file, a bad comment reference with its file and line.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "../../test_helpers.h"

namespace fs = std::filesystem;
using namespace nursing_bed::test;  // runCommand, shellQuote, writeFile, freshTestDir

namespace {

ToolResult checkLinks(const fs::path& root) {
  return runCommand("/usr/bin/python3 " +
                    shellQuote(std::string(NURSING_BED_SOURCE_DIR) + "/scripts/check_doc_links.py") + " --root " +
                    shellQuote(root.string()));
}

fs::path smallTree(const std::string& name, const std::string& readme) {
  const fs::path root = freshTestDir("links", name);
  fs::create_directories(root / "doc");
  writeFile(root / "README.md", readme);
  writeFile(root / "doc/a.md", "# Title\n\n## Some Section\n\nBack to [the readme](../README.md).\n");
  return root;
}

/// A small tree whose README and its one doc page are good, with one more file at `rel`.
fs::path treeWith(const std::string& name, const std::string& rel, const std::string& text) {
  const fs::path root = smallTree(name, "See [a](doc/a.md).\n");
  fs::create_directories((root / rel).parent_path());
  writeFile(root / rel, text);
  return root;
}

bool mentions(const ToolResult& r, const std::string& text) { return r.output.find(text) != std::string::npos; }

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

TEST(DocLinks, CommentReferencesToExistingPagesAndAnchorsPass) {
  const ToolResult r = checkLinks(treeWith("comment_good", "src/x.cpp",
                                           "// see doc/a.md and doc/a.md#some-section\n"
                                           "const char* s = \"doc/missing.md, // not a comment\";\n"
                                           "/* a block naming doc/a.md */\n"));
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(mentions(r, ", 0 broken")) << r.output;
}

TEST(DocLinks, ACommentNamingAMissingPageIsNamedWithFileAndLine) {
  const ToolResult r = checkLinks(
      treeWith("comment_missing", "include/y.h", "#pragma once\n/* first line\n   see doc/b.md */\nint y;  // fine\n"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(mentions(r, "include/y.h:3: mention of doc/b.md: no such file")) << r.output;
}

TEST(DocLinks, ACommentNamingAMissingAnchorIsNamedWithFileAndLine) {
  const ToolResult r = checkLinks(treeWith("comment_anchor", "test/t.cpp", "int t;\n// doc/a.md#no-such-section\n"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(mentions(r, "test/t.cpp:2: mention of doc/a.md#no-such-section: no heading '#no-such-section'"))
      << r.output;
}

TEST(DocLinks, CommentsOfScriptsConfigurationAndLaunchFilesAreChecked) {
  const fs::path root = treeWith("comment_kinds", "scripts/tool.py",
                                 "\"\"\"A tool (doc/c.md).\"\"\"\nx = \"doc/not_a_comment.md\"\n# doc/d.md\n");
  fs::create_directories(root / "config");
  fs::create_directories(root / "test");
  writeFile(root / "config/c.yaml", "key: 1  # doc/e.md\nurl: \"http://x#y\"\n");
  writeFile(root / "test/t.test", "<launch>\n  <!-- one\n       doc/f.md -->\n</launch>\n");
  const ToolResult r = checkLinks(root);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(mentions(r, "scripts/tool.py:1: mention of doc/c.md")) << r.output;
  EXPECT_TRUE(mentions(r, "scripts/tool.py:3: mention of doc/d.md")) << r.output;
  EXPECT_FALSE(mentions(r, "not_a_comment")) << r.output;
  EXPECT_TRUE(mentions(r, "config/c.yaml:1: mention of doc/e.md")) << r.output;
  EXPECT_TRUE(mentions(r, "test/t.test:3: mention of doc/f.md")) << r.output;
  EXPECT_TRUE(mentions(r, "4 broken")) << r.output;
}

TEST(DocLinks, AFileOutsideTheRepositoryIsFlaggedInCommentsAndPages) {
  const fs::path root = treeWith("outside", "src/z.cpp", "int z;\n// format: ../shared/run.md\n");
  writeFile(root / "doc/a.md", "# Title\n\n## Some Section\n\nAs /work/notes/x.md says.\n");
  const ToolResult r = checkLinks(root);
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(mentions(r, "src/z.cpp:2: mentions a file outside the repository (../shared)")) << r.output;
  EXPECT_TRUE(mentions(r, "doc/a.md:5: mentions a file outside the repository (/work/)")) << r.output;
}

TEST(DocLinks, ABareMarkdownNameThatIsNoPageOfTheRepositoryIsFlagged) {
  const ToolResult r =
      checkLinks(treeWith("bare", "src/w.cpp", "// a.md is fine; the format of run-format.md is not here\n"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(mentions(r, "src/w.cpp:1: mention of run-format.md: no such page in the repository")) << r.output;
  EXPECT_FALSE(mentions(r, "mention of a.md")) << r.output;
}
