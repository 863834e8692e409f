// The command line of one subcommand: which options it takes, and their values checked and converted.
//
// Accepted forms: "--name value", "--name=value" and, for one-letter options, "-k value". Every
// problem (unknown option, missing or repeated option, a value that is not a number or out of range)
// throws UsageError, which the command turns into exit code 2.
#pragma once

#include <cstddef>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace kdspace::cli {

/// A mistake in the command line (as opposed to bad data): exit code 2.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct OptionSpec {
  std::string name;         ///< with its dashes: "--base", "-k"
  bool takes_value = true;  ///< false: a flag such as "--stats"
  /// When set, the option is recognised but refused with this reason (e.g. "not available yet").
  std::string refused_because = {};
};

class Options {
 public:
  /// Parses args (the words after the subcommand). Throws UsageError.
  Options(const std::vector<std::string>& args, const std::vector<OptionSpec>& specs);

  bool has(const std::string& name) const { return values_.count(name) > 0; }

  /// The value of a required option (UsageError "missing option NAME" when absent).
  const std::string& required(const std::string& name) const;
  /// The value, or `fallback` when the option is absent.
  std::string text(const std::string& name, const std::string& fallback = {}) const;

  /// A whole number in [lo, hi]; `fallback` when absent.
  std::size_t count(const std::string& name, std::size_t fallback, std::size_t lo, std::size_t hi) const;
  /// A finite number in [lo, hi]; `fallback` when absent.
  double number(const std::string& name, double fallback, double lo, double hi) const;
  /// Comma-separated finite numbers in [lo, hi] ("1,2.5,3"); empty when absent.
  std::vector<double> numbers(const std::string& name, double lo, double hi) const;
  /// One of `allowed`; `fallback` when absent.
  std::string choice(const std::string& name, const std::string& fallback,
                     const std::vector<std::string>& allowed) const;

 private:
  std::map<std::string, std::string> values_;  // a flag maps to ""
};

/// Whether the words ask for help ("--help" or "-h" anywhere).
bool wants_help(const std::vector<std::string>& args);

/// Throws UsageError unless `path` ends with `extension` (".ivecs"; letter case ignored).
void require_extension(const std::string& option, const std::string& path, const std::string& extension);

}  // namespace kdspace::cli
