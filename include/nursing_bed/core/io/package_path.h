// Where the package's shared files (config/, data/, scripts/, urdf/) are, found at run time: no
// build's source path is compiled in, so an installed package reads its own share folder and a
// checkout its own tree.
#pragma once

#include <string>
#include <vector>

namespace nursing_bed {

/// The folders tried for the package, in order:
///  1. `explicit_dir` alone, when not empty (a command-line option or a parameter: a wrong one
///     is an error, not a reason to look elsewhere);
///  2. each ROS_PACKAGE_PATH entry that is, or directly holds, a package named nursing_bed (by
///     its package.xml), as rospack finds it;
///  3. the running executable's prefix (/proc/self/exe, <prefix>/lib/nursing_bed/<program>): an
///     install's <prefix>/share/nursing_bed, then the source folders a catkin devel prefix lists
///     in its .catkin file, searched like ROS_PACKAGE_PATH entries.
std::vector<std::string> packageDirCandidates(const std::string& explicit_dir = "");

/// The first of packageDirCandidates(explicit_dir) that holds `relative` (a file or a folder,
/// e.g. "config"). Throws std::runtime_error naming `relative` and every folder tried when none
/// does.
std::string findPackageDir(const std::string& relative, const std::string& explicit_dir = "");

/// findPackageDir(relative, explicit_dir) + "/" + relative.
std::string findPackageFile(const std::string& relative, const std::string& explicit_dir = "");

}  // namespace nursing_bed
