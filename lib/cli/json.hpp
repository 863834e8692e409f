// A flat JSON object written key by key, for --stats.
#pragma once

#include <cstdint>
#include <string>

namespace kdspace::cli {

class JsonObject {
 public:
  JsonObject& add(const std::string& key, double value);  ///< non-finite values are written as null
  JsonObject& add(const std::string& key, std::uint64_t value);
  JsonObject& add(const std::string& key, unsigned value) { return add(key, std::uint64_t{value}); }
  JsonObject& add(const std::string& key, const std::string& value);
  JsonObject& add(const std::string& key, const char* value) { return add(key, std::string(value)); }
  /// The object on one line: {"a": 1, "b": "x"}.
  std::string str() const { return "{" + body_ + "}"; }

 private:
  void key(const std::string& k);
  std::string body_;
};

/// s as a JSON string literal, with its quotes.
std::string json_string(const std::string& s);

}  // namespace kdspace::cli
