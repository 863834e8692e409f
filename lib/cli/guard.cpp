#include "guard.hpp"

#include <cstdio>
#include <exception>
#include <new>

#include "kdspace/error.hpp"
#include "options.hpp"

namespace kdspace::cli {

void print_error(const std::string& what) {
  std::fprintf(stderr, "kdspace: error: %s\n", what.c_str());
}

int run_guarded(const std::string& command, const std::function<int()>& body) {
  try {
    return body();
  } catch (const UsageError& e) {
    print_error(e.what());
    std::fprintf(stderr, "run 'kdspace %s --help'\n", command.c_str());
    return 2;
  } catch (const kdspace::Error& e) {
    print_error(e.what());
  } catch (const std::bad_alloc&) {
    print_error("out of memory: the data or the results do not fit in this machine's memory");
  } catch (const std::exception& e) {
    print_error(e.what());
  } catch (...) {
    print_error("unexpected internal error");
  }
  return 1;
}

}  // namespace kdspace::cli
