// Command lines of the tools (CLI11): one convention for help and mistakes. Each tool's help
// starts with its synopsis ("usage: ..."), given as the app's description; CLI11 lists the
// options from their definitions. A mistake prints the help and a message naming the argument
// to stderr and exits with 2, before anything is written.
#pragma once

#include <CLI/CLI.hpp>

#include <cmath>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace nursing_bed {
namespace tools {

constexpr int kExitBadArguments = 2;
/// What parseCommandLine returns when the tool should run.
constexpr int kRun = -1;

/// A command-line mistake found after parsing (a bad value, a missing argument).
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Help starts with the synopsis: a subcommand's registered one (its description stays the
/// one-line summary its parent lists), else the app's description. CLI11's own "Usage:" line
/// would repeat it.
class SynopsisFormatter : public CLI::Formatter {
 public:
  void setSynopsis(const CLI::App* app, std::string text) { synopses_[app] = std::move(text); }
  std::string make_description(const CLI::App* app) const override {
    const auto it = synopses_.find(app);
    return it == synopses_.end() ? CLI::Formatter::make_description(app) : it->second + "\n";
  }
  std::string make_usage(const CLI::App*, std::string) const override { return ""; }

 private:
  std::map<const CLI::App*, std::string> synopses_;
};

/// Sets `app` (and subcommands added later, which share its formatter) up: the synopsis
/// formatter, and unknown arguments kept for checkNoExtras to name instead of CLI11's generic
/// message.
inline void configureApp(CLI::App& app) {
  app.formatter(std::make_shared<SynopsisFormatter>());
  app.allow_extras();
  // As before CLI11: an option given twice keeps its last value.
  app.option_defaults()->always_capture_default()->multi_option_policy(CLI::MultiOptionPolicy::TakeLast);
}

/// The synopsis `sub`'s help starts with (sub was added to an app set up by configureApp).
inline void setSynopsis(CLI::App& sub, const std::string& text) {
  if (const auto f = std::dynamic_pointer_cast<SynopsisFormatter>(sub.get_formatter())) f->setSynopsis(&sub, text);
}

/// An option (or positional) that keeps every value it is given, one per occurrence:
/// `--effect a --effect b`. (The default keeps the last value only.)
inline CLI::Option* takeAll(CLI::Option* option) {
  return option->multi_option_policy(CLI::MultiOptionPolicy::TakeAll)->default_str("");
}

/// "NAME=VALUE" split at its first '=' (the value may hold more); nullopt without a name or '='.
inline std::optional<std::pair<std::string, std::string>> splitKeyValue(const std::string& item) {
  const std::size_t eq = item.find('=');
  if (eq == 0 || eq == std::string::npos) return std::nullopt;
  return std::make_pair(item.substr(0, eq), item.substr(eq + 1));
}

/// Accepts a finite number > 0 (CLI11's PositiveNumber names the whole double range instead).
inline CLI::Validator positiveNumber() {
  return CLI::Validator(
      [](std::string& text) {
        std::size_t used = 0;
        double value = 0.0;
        try {
          value = std::stod(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used > 0 && used == text.size() && std::isfinite(value) && value > 0.0) return std::string();
        return "expected a number > 0, got '" + text + "'";
      },
      "> 0");
}

/// Throws a UsageError naming the first argument `app` (or its chosen subcommand) did not take.
inline void checkNoExtras(const CLI::App& app) {
  const std::vector<std::string> extras = app.remaining(true);
  if (extras.empty()) return;
  for (const std::string& a : extras)
    if (a.size() > 1 && a[0] == '-') throw UsageError("unknown option '" + a + "'");
  throw UsageError("unexpected argument '" + extras.front() + "'");
}

/// CLI11's message, with a missing option value said in words.
inline std::string mistakeText(const CLI::ParseError& e) {
  // "<option>: <n> required <type> missing", read without a regex (bounded, no recursion).
  const std::string what = e.what();
  const std::size_t colon = what.find(": ");
  const std::size_t required = what.find(" required ");
  const bool missing = what.size() > 8 && what.compare(what.size() - 8, 8, " missing") == 0;
  if (colon == std::string::npos || required == std::string::npos || !missing || required < colon) return what;
  const std::string option = what.substr(0, colon), count = what.substr(colon + 2, required - colon - 2);
  const bool digits = !count.empty() && count.find_first_not_of("0123456789") == std::string::npos;
  const std::string type = what.substr(required + 10, what.size() - 8 - required - 10);
  if (!digits || option.empty() || option.find(' ') != std::string::npos || type.empty() ||
      type.find(' ') != std::string::npos)
    return what;
  return option + " needs a value";
}

/// Prints the help of `app` (its chosen subcommand's, when there is one) and "`prefix`: `message`"
/// to stderr; returns kExitBadArguments.
inline int reportMistake(const CLI::App& app, const std::string& prefix, const std::string& message) {
  std::cerr << app.help() << prefix << ": " << message << "\n";
  return kExitBadArguments;
}

/// Parses the command line. kRun when the tool should run; 0 after --help (printed to stdout);
/// kExitBadArguments after a mistake (reported by reportMistake with the tool's name).
inline int parseCommandLine(CLI::App& app, int argc, char** argv) {
  try {
    app.parse(argc, argv);
    checkNoExtras(app);
  } catch (const CLI::CallForHelp&) {
    std::cout << app.help();
    return 0;
  } catch (const CLI::ParseError& e) {
    // An argument CLI11 did not take explains a missing one ("fe_airbag bogus": no mode).
    try {
      checkNoExtras(app);
    } catch (const UsageError& extra) {
      return reportMistake(app, app.get_name(), extra.what());
    }
    return reportMistake(app, app.get_name(), mistakeText(e));
  } catch (const UsageError& e) {
    return reportMistake(app, app.get_name(), e.what());
  }
  return kRun;
}

}  // namespace tools
}  // namespace nursing_bed
