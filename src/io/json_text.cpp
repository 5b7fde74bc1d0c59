#include "desplat/io/json_text.hpp"

#include <iterator>

namespace desplat {

namespace {

// nlohmann's parser callback receives the depth of every event: refusing at the first event
// beyond the bound stops the parse before the deep part is built.
template <class Input>
nlohmann::json parse_with_bound(Input&& input, const std::string& source, bool ignore_comments) {
  // `depth` is that of the enclosing value: an array or object opened at depth d is level d + 1.
  const nlohmann::json::parser_callback_t bound = [&source](int depth, nlohmann::json::parse_event_t event,
                                                            nlohmann::json&) {
    const bool opens =
        event == nlohmann::json::parse_event_t::object_start || event == nlohmann::json::parse_event_t::array_start;
    if (opens && depth >= kMaxJsonDepth)
      throw JsonTextError(source + ": JSON nested deeper than " + std::to_string(kMaxJsonDepth) +
                          " levels (arrays or objects inside one another); desplat's files nest a few levels, so "
                          "this is not one of them: check the file or text given");
    return true;
  };
  try {
    return nlohmann::json::parse(std::forward<Input>(input), bound, /*allow_exceptions=*/true, ignore_comments);
  } catch (const nlohmann::json::parse_error& e) {
    throw JsonTextError(source + " is not valid JSON: " + json_error_text(e));
  }
}

}  // namespace

std::string json_error_text(const nlohmann::json::exception& e) {
  const std::string what = e.what();
  const size_t end = what.find("] ");
  return what.rfind("[json.exception.", 0) == 0 && end != std::string::npos ? what.substr(end + 2) : what;
}

nlohmann::json parse_json_bounded(std::string_view text, const std::string& source, bool ignore_comments) {
  return parse_with_bound(text, source, ignore_comments);
}

nlohmann::json parse_json_bounded(std::istream& in, const std::string& source, bool ignore_comments) {
  const std::string text{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  return parse_with_bound(std::string_view(text), source, ignore_comments);
}

}  // namespace desplat
