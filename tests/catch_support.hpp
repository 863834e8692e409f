// Helpers for test files that use Catch: what a failing call says.
#ifndef KDSPACE_TESTS_CATCH_SUPPORT_HPP
#define KDSPACE_TESTS_CATCH_SUPPORT_HPP

#include <catch2/catch.hpp>
#include <exception>
#include <string>

#include "kdspace/error.hpp"

namespace kdspace_test {

/// The message of the kdspace::Error that f throws. Any other outcome fails a check and returns a text
/// that names it, so that a comparison or a Contains() matcher on the message fails as well.
template <class F>
std::string error_message(F&& f) {
  try {
    f();
  } catch (const kdspace::Error& e) {
    return e.what();
  } catch (const std::exception& e) {
    FAIL_CHECK("not a kdspace::Error: " << e.what());
    return std::string("<not a kdspace::Error: ") + e.what() + ">";
  }
  FAIL_CHECK("no kdspace::Error was thrown");
  return "<no exception>";
}

}  // namespace kdspace_test

#endif  // KDSPACE_TESTS_CATCH_SUPPORT_HPP
