#include "options.hpp"

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

namespace kdspace::cli {

namespace {

const OptionSpec* find_spec(const std::vector<OptionSpec>& specs, const std::string& name) {
  for (const OptionSpec& s : specs)
    if (s.name == name) return &s;
  return nullptr;
}

// A word that reads as another option rather than as a value ("--stats", "-k"); "-3" and "-0.5" are
// values (so that "-k -3" is reported as a bad number, not as a missing one).
bool looks_like_option(const std::string& word) {
  if (word.size() < 2 || word[0] != '-') return false;
  return !(std::isdigit(static_cast<unsigned char>(word[1])) || word[1] == '.');
}

std::string lowercase(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

}  // namespace

Options::Options(const std::vector<std::string>& args, const std::vector<OptionSpec>& specs) {
  for (std::size_t i = 0; i < args.size(); ++i) {
    std::string name = args[i];
    std::string value;
    bool inline_value = false;
    if (name.rfind("--", 0) == 0) {
      const std::size_t eq = name.find('=');
      if (eq != std::string::npos) {
        value = name.substr(eq + 1);
        name.resize(eq);
        inline_value = true;
      }
    } else if (name.size() < 2 || name[0] != '-') {
      throw UsageError("unexpected argument '" + name + "'");
    }
    const OptionSpec* spec = find_spec(specs, name);
    if (!spec) throw UsageError("unknown option '" + name + "'");
    if (!spec->refused_because.empty()) throw UsageError("option " + name + " is " + spec->refused_because);
    if (values_.count(name)) throw UsageError("option " + name + " is given twice");
    if (spec->takes_value && !inline_value) {
      if (i + 1 >= args.size() || looks_like_option(args[i + 1]))
        throw UsageError("option " + name + " needs a value");
      value = args[++i];
    } else if (!spec->takes_value && inline_value) {
      throw UsageError("option " + name + " takes no value");
    }
    if (spec->takes_value && value.empty()) throw UsageError("option " + name + " needs a non-empty value");
    values_[name] = value;
  }
}

const std::string& Options::required(const std::string& name) const {
  const auto it = values_.find(name);
  if (it == values_.end()) throw UsageError("missing option " + name);
  return it->second;
}

std::string Options::text(const std::string& name, const std::string& fallback) const {
  const auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second;
}

std::size_t Options::count(const std::string& name, std::size_t fallback, std::size_t lo,
                           std::size_t hi) const {
  const auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  const std::string& s = it->second;
  const std::string range = hi == std::numeric_limits<std::size_t>::max()
                                ? "a whole number >= " + std::to_string(lo)
                                : "a whole number from " + std::to_string(lo) + " to " + std::to_string(hi);
  bool digits = !s.empty();
  for (char c : s) digits = digits && std::isdigit(static_cast<unsigned char>(c));
  if (!digits) throw UsageError("option " + name + " expects " + range + ", got '" + s + "'");
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), nullptr, 10);
  if (errno == ERANGE || v < lo || v > hi)
    throw UsageError("option " + name + " expects " + range + ", got " + s);
  return static_cast<std::size_t>(v);
}

namespace {

// One number of option `name` in [lo, hi] (finite); UsageError otherwise.
double parse_number(const std::string& name, const std::string& s, double lo, double hi) {
  char* end = nullptr;
  errno = 0;
  const double v = std::strtod(s.c_str(), &end);
  const bool parsed =
      !s.empty() && !std::isspace(static_cast<unsigned char>(s[0])) && end == s.c_str() + s.size();
  auto show = [](double x) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", x);
    return std::string(buf);
  };
  const std::string range =
      std::isinf(hi) ? "a finite number >= " + show(lo) : "a number from " + show(lo) + " to " + show(hi);
  if (!parsed || errno == ERANGE || !std::isfinite(v) || v < lo || v > hi)
    throw UsageError("option " + name + " expects " + range + ", got '" + s + "'");
  return v;
}

}  // namespace

double Options::number(const std::string& name, double fallback, double lo, double hi) const {
  const auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  return parse_number(name, it->second, lo, hi);
}

std::vector<double> Options::numbers(const std::string& name, double lo, double hi) const {
  std::vector<double> out;
  const auto it = values_.find(name);
  if (it == values_.end()) return out;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = it->second.find(',', start);
    out.push_back(parse_number(name, it->second.substr(start, comma - start), lo, hi));
    if (comma == std::string::npos) return out;
    start = comma + 1;
  }
}

std::string Options::choice(const std::string& name, const std::string& fallback,
                            const std::vector<std::string>& allowed) const {
  const auto it = values_.find(name);
  if (it == values_.end()) return fallback;
  for (const std::string& a : allowed)
    if (it->second == a) return a;
  std::string list;
  for (std::size_t i = 0; i < allowed.size(); ++i)
    list += (i ? (i + 1 == allowed.size() ? " or " : ", ") : "") + allowed[i];
  throw UsageError("option " + name + " expects " + list + ", got '" + it->second + "'");
}

bool wants_help(const std::vector<std::string>& args) {
  for (const std::string& a : args)
    if (a == "--help" || a == "-h") return true;
  return false;
}

void require_extension(const std::string& option, const std::string& path, const std::string& extension) {
  const std::string p = lowercase(path);
  if (p.size() <= extension.size() ||
      p.compare(p.size() - extension.size(), extension.size(), extension) != 0)
    throw UsageError("option " + option + " names a " + extension + " file, got '" + path + "'");
}

}  // namespace kdspace::cli
