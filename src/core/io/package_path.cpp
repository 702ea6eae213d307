#include "nursing_bed/core/io/package_path.h"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <stdexcept>
#include <string_view>

namespace nursing_bed {
namespace {

namespace fs = std::filesystem;

constexpr const char* kPackageName = "nursing_bed";

/// True when `dir` holds a package.xml naming this package.
bool isThisPackage(const fs::path& dir) {
  // The name is near the top of a package.xml: a bounded read, searched without a regex.
  constexpr std::size_t kMaxBytes = 64 * 1024;
  std::ifstream in(dir / "package.xml");
  if (!in) return false;
  std::string xml(kMaxBytes, '\0');
  in.read(xml.data(), static_cast<std::streamsize>(xml.size()));
  xml.resize(static_cast<std::size_t>(in.gcount()));
  const std::size_t open = xml.find("<name>");
  if (open == std::string::npos) return false;
  const std::size_t close = xml.find("</name>", open);
  if (close == std::string::npos) return false;
  const std::string_view blanks = " \t\r\n";
  std::string_view name(xml.data() + open + 6, close - open - 6);
  name.remove_prefix(std::min(name.find_first_not_of(blanks), name.size()));
  name.remove_suffix(name.size() - std::min(name.find_last_not_of(blanks) + 1, name.size()));
  return name == kPackageName;
}

/// `entry` itself when it is this package, else its direct subfolders that are (a workspace's
/// src/ folder). Unreadable folders are skipped: the path may list folders that are gone.
void addPackagesIn(const fs::path& entry, std::vector<std::string>* out) {
  std::error_code ec;
  if (entry.empty() || !fs::is_directory(entry, ec)) return;
  if (isThisPackage(entry)) {
    out->push_back(entry.string());
    return;
  }
  for (fs::directory_iterator it(entry, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_directory(ec) && isThisPackage(it->path())) out->push_back(it->path().string());
}

/// The entries of a ':' or ';' separated list (ROS_PACKAGE_PATH, a .catkin file).
std::vector<fs::path> splitPathList(const std::string& text, char separator) {
  std::vector<fs::path> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, separator))
    if (!item.empty()) out.emplace_back(item);
  return out;
}

/// The executable's install or devel prefix candidates (step 3 of packageDirCandidates).
void addExecutablePrefix(std::vector<std::string>* out) {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return;
  const fs::path prefix = exe.parent_path().parent_path().parent_path();
  out->push_back((prefix / "share" / kPackageName).string());
  std::ifstream catkin(prefix / ".catkin");
  std::string sources;
  if (catkin && std::getline(catkin, sources))
    for (const fs::path& source : splitPathList(sources, ';')) addPackagesIn(source, out);
}

}  // namespace

std::vector<std::string> packageDirCandidates(const std::string& explicit_dir) {
  if (!explicit_dir.empty()) return {explicit_dir};
  std::vector<std::string> out;
  if (const char* ros_package_path = std::getenv("ROS_PACKAGE_PATH"))
    for (const fs::path& entry : splitPathList(ros_package_path, ':')) addPackagesIn(entry, &out);
  addExecutablePrefix(&out);
  return out;
}

std::string findPackageDir(const std::string& relative, const std::string& explicit_dir) {
  const std::vector<std::string> candidates = packageDirCandidates(explicit_dir);
  std::error_code ec;
  for (const std::string& dir : candidates)
    if (fs::exists(fs::path(dir) / relative, ec)) return dir;
  std::string tried;
  for (const std::string& dir : candidates) tried += (tried.empty() ? "" : ", ") + dir;
  throw std::runtime_error(std::string(kPackageName) + " package folder with '" + relative + "' not found (tried: " +
                           (tried.empty() ? "nothing: no ROS_PACKAGE_PATH and no executable path" : tried) +
                           "); give the folder explicitly or set ROS_PACKAGE_PATH");
}

std::string findPackageFile(const std::string& relative, const std::string& explicit_dir) {
  return (fs::path(findPackageDir(relative, explicit_dir)) / relative).string();
}

}  // namespace nursing_bed
