// Reading JSON text with bounded nesting: the one parse entry point for every JSON file or
// option desplat reads (--config, a model folder's config.json, a scene description, a bench
// grid, a checkpoint's metadata).
//
// Why bounded: code that walks a parsed document (lookups, dumps, error messages) recurses
// once per level, so a document nested tens of thousands of levels deep exhausts the stack.
// No file desplat writes or reads nests deeper than a handful of levels; kMaxJsonDepth leaves
// ample room and refuses the rest with a clear error before anything walks the document.
#pragma once

#include <istream>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>

namespace desplat {

inline constexpr int kMaxJsonDepth = 256;

// The text is not JSON, or nests deeper than kMaxJsonDepth. what() names the source and the
// problem without nlohmann's "[json.exception…]" prefix, e.g.
//   "config.json is not valid JSON: parse error at line 1, column 3: syntax error …",
//   "config.json: JSON nested deeper than 256 levels (arrays or objects inside one another); …".
class JsonTextError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Parses `text` (the whole document). `source` names it in errors ("config file a.json",
// "--config text"). Throws JsonTextError.
nlohmann::json parse_json_bounded(std::string_view text, const std::string& source, bool ignore_comments = false);
// The same for a whole stream (read to its end).
nlohmann::json parse_json_bounded(std::istream& in, const std::string& source, bool ignore_comments = false);

// A JSON library error's message without its "[json.exception.type_error.302] " prefix, for
// messages that quote it ("type must be number, but is string").
std::string json_error_text(const nlohmann::json::exception& e);

}  // namespace desplat
