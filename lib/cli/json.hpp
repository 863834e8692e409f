// A flat JSON object written key by key, for --stats.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace kdspace::cli {

class JsonObject {
 public:
  JsonObject& add(const std::string& key, double value);  ///< non-finite values are written as null
  JsonObject& add(const std::string& key, std::uint64_t value);
  JsonObject& add(const std::string& key, unsigned value) { return add(key, std::uint64_t{value}); }
  JsonObject& add(const std::string& key, const std::string& value);
  JsonObject& add(const std::string& key, const char* value) { return add(key, std::string(value)); }
  /// An array of numbers, each in the shortest form that reads back exactly.
  JsonObject& add(const std::string& key, const std::vector<double>& values);
  JsonObject& add(const std::string& key, const std::vector<std::uint64_t>& values);
  /// The object on one line: {"a": 1, "b": "x"}.
  std::string str() const { return "{" + body_ + "}"; }

 private:
  void key(const std::string& k);
  std::string body_;
};

/// s as a JSON string literal, with its quotes.
std::string json_string(const std::string& s);

}  // namespace kdspace::cli
