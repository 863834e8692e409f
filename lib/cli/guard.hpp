// Turns whatever a subcommand throws into a message on stderr and an exit code.
#pragma once

#include <functional>
#include <string>

namespace kdspace::cli {

/// Runs body and returns its exit code; on an exception prints "kdspace: error: ..." to stderr and
/// returns 2 for a UsageError (followed by the hint "run 'kdspace COMMAND --help'") or 1 for
/// anything else (bad data, I/O, out of memory).
int run_guarded(const std::string& command, const std::function<int()>& body);

/// Prints "kdspace: error: WHAT" to stderr.
void print_error(const std::string& what);

}  // namespace kdspace::cli
