// Standard 3DGS PLY export and import (see include/desplat/io/ply.hpp for the format).
//
// Both directions share one table of columns (property name → place in a
// GaussianSet), so the written order and the read mapping cannot drift apart. The
// reader is strict: it rejects anything it would have to guess about or drop.
#include "desplat/io/ply.hpp"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <optional>
#include <ostream>
#include <set>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "desplat/io/atomic_file.hpp"

namespace desplat {
namespace fs = std::filesystem;

namespace {

// A real header is ~1.5 KB; the bound keeps a file without end_header from being
// scanned to the end.
constexpr std::size_t kMaxHeaderBytes = std::size_t{1} << 20;
constexpr std::size_t kChunkBytes = std::size_t{4} << 20;  // I/O buffer size
constexpr const char* kSupportedFormat = "binary_little_endian 1.0";

[[noreturn]] void fail(const fs::path& path, const std::string& what) { throw PlyError(path.string() + ": " + what); }

// ---------------------------------------------------------------------------
// Column table shared by writer and reader.

enum class Field { Mean, LogScale, Quat, Opacity, Color, Normal };

struct Column {
  std::string name;
  Field field;
  int offset;  // index within the Gaussian's slice of the field's array
};

int stride_of(Field field, int sh_degree) {
  switch (field) {
    case Field::Mean:
    case Field::LogScale:
      return 3;
    case Field::Quat:
      return 4;
    case Field::Opacity:
      return 1;
    case Field::Color:
      return 3 * sh_coeff_count(sh_degree);
    case Field::Normal:
      return 0;
  }
  return 0;
}

// The standard 3DGS property order. f_rest is channel-major in the file while
// colors are [K, 3] coefficient-major per Gaussian: f_rest_j holds channel
// j / (K-1) of coefficient 1 + j % (K-1).
std::vector<Column> standard_columns(int sh_degree) {
  const int rest = sh_coeff_count(sh_degree) - 1;
  std::vector<Column> cols;
  for (int a = 0; a < 3; ++a) cols.push_back({std::string(1, "xyz"[a]), Field::Mean, a});
  for (int a = 0; a < 3; ++a) cols.push_back({std::string("n") + "xyz"[a], Field::Normal, 0});
  for (int c = 0; c < 3; ++c) cols.push_back({"f_dc_" + std::to_string(c), Field::Color, c});
  for (int j = 0; j < 3 * rest; ++j) {
    const int channel = j / rest, coeff = 1 + j % rest;
    cols.push_back({"f_rest_" + std::to_string(j), Field::Color, 3 * coeff + channel});
  }
  cols.push_back({"opacity", Field::Opacity, 0});
  for (int a = 0; a < 3; ++a) cols.push_back({"scale_" + std::to_string(a), Field::LogScale, a});
  for (int a = 0; a < 4; ++a) cols.push_back({"rot_" + std::to_string(a), Field::Quat, a});
  return cols;
}

const std::vector<float>* array_of(const GaussianSet& g, Field field) {
  switch (field) {
    case Field::Mean:
      return &g.means;
    case Field::LogScale:
      return &g.log_scales;
    case Field::Quat:
      return &g.quats;
    case Field::Opacity:
      return &g.opacity_logits;
    case Field::Color:
      return &g.colors;
    case Field::Normal:
      return nullptr;
  }
  return nullptr;
}

// Non-const twin of the above; the cast is sound because `g` itself is mutable.
std::vector<float>* array_of(GaussianSet& g, Field field) {
  return const_cast<std::vector<float>*>(array_of(std::as_const(g), field));
}

// Little-endian float (de)serialization independent of the host byte order.
float load_le_float(const unsigned char* p) {
  const std::uint32_t u =
      std::uint32_t{p[0]} | std::uint32_t{p[1]} << 8 | std::uint32_t{p[2]} << 16 | std::uint32_t{p[3]} << 24;
  return std::bit_cast<float>(u);
}

void store_le_float(float v, unsigned char* p) {
  const auto u = std::bit_cast<std::uint32_t>(v);
  for (int b = 0; b < 4; ++b) p[b] = static_cast<unsigned char>(u >> (8 * b));
}

std::string describe_nonfinite(float v) {
  if (std::isnan(v)) return "NaN";
  return v > 0 ? "+Inf" : "-Inf";
}

// ---------------------------------------------------------------------------
// Writer.

void check_exportable(const fs::path& path, const GaussianSet& g, const WorldNormalization& norm) {
  if (g.color_mode == ColorMode::RGB)
    fail(path,
         "cannot export RGB-mode Gaussians (distractors) as a 3DGS PLY; "
         "the format stores spherical-harmonics color only");
  try {
    g.view().validate();
  } catch (const std::invalid_argument& e) {
    fail(path, std::string("cannot export inconsistent Gaussians: ") + e.what());
  }
  if (!(norm.scale > 0) || !std::isfinite(norm.scale))
    fail(path, "world normalization scale must be positive and finite (got " + std::to_string(norm.scale) + ")");
  for (double c : norm.center)
    if (!std::isfinite(c)) fail(path, "world normalization center is not finite");
}

// Converts one stored value to the original frame, in double with a single rounding
// to float (same formulas as WorldNormalization::to_original). The identity
// normalization copies verbatim so that export is bit-lossless (even for -0).
class ToOriginal {
 public:
  explicit ToOriginal(const WorldNormalization& norm)
      : norm_(norm),
        identity_(norm.scale == 1 && norm.center == std::array<double, 3>{0, 0, 0}),
        log_scale_(std::log(norm.scale)) {}

  float operator()(Field field, int offset, float v) const {
    if (identity_) return v;
    if (field == Field::Mean) return static_cast<float>(double{v} / norm_.scale + norm_.center[offset]);
    if (field == Field::LogScale) return static_cast<float>(double{v} - log_scale_);
    return v;  // quaternions, SH and opacity do not depend on the frame
  }

 private:
  WorldNormalization norm_;
  bool identity_;
  double log_scale_;
};

// A column resolved to its array: value of Gaussian i is base[i * stride + offset].
struct Source {
  const Column* column;
  const float* base;  // null for normals (written as 0)
  std::size_t stride;
};

std::vector<Source> sources_of(const GaussianSet& g, const std::vector<Column>& cols) {
  std::vector<Source> sources;
  for (const Column& c : cols) {
    const std::vector<float>* array = array_of(g, c.field);
    sources.push_back({&c, array ? array->data() : nullptr, static_cast<std::size_t>(stride_of(c.field, g.sh_degree))});
  }
  return sources;
}

std::string header_text(std::size_t n, const std::vector<Column>& cols) {
  std::string h = "ply\nformat " + std::string(kSupportedFormat) + "\nelement vertex " + std::to_string(n) + "\n";
  for (const Column& c : cols) h += "property float " + c.name + "\n";
  return h + "end_header\n";
}

// Encodes Gaussians [first, first + count) as packed little-endian records into `out`.
void encode_records(const fs::path& path, const std::vector<Source>& sources, std::size_t first, std::size_t count,
                    const ToOriginal& convert, unsigned char* out) {
  for (std::size_t i = first; i < first + count; ++i) {
    for (const Source& s : sources) {
      float v = 0;  // normals
      if (s.base) {
        v = convert(s.column->field, s.column->offset, s.base[i * s.stride + s.column->offset]);
        // A value our own reader would reject must not reach the file.
        if (!std::isfinite(v))
          fail(path, "Gaussian " + std::to_string(i) + " property '" + s.column->name + "' is " +
                         describe_nonfinite(v) + " in the original frame");
      }
      store_le_float(v, out);
      out += 4;
    }
  }
}

std::string errno_text() { return std::error_code(errno, std::generic_category()).message(); }

}  // namespace

void write_gaussian_ply(const fs::path& path, const GaussianSet& gaussians, const WorldNormalization& norm) {
  check_exportable(path, gaussians, norm);
  const std::vector<Column> cols = standard_columns(gaussians.sh_degree);
  const ToOriginal convert(norm);
  const std::size_t n = gaussians.size(), record = 4 * cols.size();

  const std::vector<Source> sources = sources_of(gaussians, cols);
  const auto write_body = [&](std::ostream& out) {
    const std::string header = header_text(n, cols);
    out.write(header.data(), static_cast<std::streamsize>(header.size()));
    const std::size_t per_chunk = std::max<std::size_t>(1, kChunkBytes / record);
    std::vector<unsigned char> buf(std::min(n, per_chunk) * record);
    for (std::size_t first = 0; first < n; first += per_chunk) {
      const std::size_t count = std::min(per_chunk, n - first);
      encode_records(path, sources, first, count, convert, buf.data());
      out.write(reinterpret_cast<const char*>(buf.data()), static_cast<std::streamsize>(count * record));
    }
  };
  try {
    write_file_atomically(path, write_body);
  } catch (const AtomicWriteError& e) {
    throw PlyError(e.what());  // already starts with the path
  }
}

// ---------------------------------------------------------------------------
// Reader.

namespace {

struct Property {
  std::string name, type;
  bool is_list = false;
};

struct Element {
  std::string name;
  std::uint64_t count = 0;
  std::vector<Property> properties;
};

struct Header {
  std::vector<Element> elements;
  std::size_t bytes = 0;  // up to and including the end_header line break
};

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

// Header lines can hold binary garbage when the file is not a PLY: quote them short.
std::string quote(std::string_view s) {
  std::string q = "'";
  for (char ch : s.substr(0, 80)) q += (ch >= 32 && ch < 127) ? ch : '?';
  return q + (s.size() > 80 ? "...'" : "'");
}

class HeaderParser {
 public:
  HeaderParser(const fs::path& path, std::string_view text, bool text_is_whole_file)
      : path_(path), text_(text), whole_file_(text_is_whole_file) {}

  Header parse() {
    const auto magic = next_line();
    if (!magic || *magic != "ply")
      fail(path_, text_.empty() ? "not a PLY file (empty)" : "not a PLY file (does not start with a 'ply' line)");
    while (true) {
      const auto line = next_line();
      if (!line) fail_no_end_header();
      const auto words = split_words(*line);
      if (words.empty()) continue;
      if (words[0] == "end_header" && words.size() == 1) break;
      handle(words, *line);
    }
    if (!format_seen_) fail(path_, "header has no format line; supported: " + std::string(kSupportedFormat));
    header_.bytes = pos_;
    return std::move(header_);
  }

 private:
  std::optional<std::string_view> next_line() {
    const std::size_t nl = text_.find('\n', pos_);
    if (nl == std::string_view::npos) return std::nullopt;
    std::string_view line = text_.substr(pos_, nl - pos_);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    pos_ = nl + 1;
    ++line_no_;
    return line;
  }

  [[noreturn]] void fail_no_end_header() const {
    fail(path_, whole_file_ ? "header has no end_header line"
                            : "no end_header line within the first " + std::to_string(kMaxHeaderBytes) +
                                  " bytes (not a PLY header, or a corrupt one)");
  }

  [[noreturn]] void fail_line(const std::string& what, std::string_view line) const {
    fail(path_, "header line " + std::to_string(line_no_) + " " + quote(line) + ": " + what);
  }

  void handle(const std::vector<std::string_view>& w, std::string_view line) {
    if (w[0] == "comment" || w[0] == "obj_info") return;
    if (w[0] == "format") return handle_format(w, line);
    if (w[0] == "element") return handle_element(w, line);
    if (w[0] == "property") return handle_property(w, line);
    fail_line("unexpected keyword", line);
  }

  void handle_format(const std::vector<std::string_view>& w, std::string_view line) {
    const std::string supported = std::string("only ") + kSupportedFormat + " is supported";
    if (format_seen_) fail_line("second format line", line);
    if (w.size() != 3) fail_line("expected 'format <type> <version>'", line);
    if (w[1] == "ascii") fail(path_, "ascii PLY is not supported; " + supported);
    if (w[1] == "binary_big_endian") fail(path_, "big-endian binary PLY is not supported; " + supported);
    if (w[1] != "binary_little_endian") fail_line("unknown format; " + supported, line);
    if (w[2] != "1.0") fail_line("unsupported PLY version; " + supported, line);
    format_seen_ = true;
  }

  void handle_element(const std::vector<std::string_view>& w, std::string_view line) {
    if (w.size() != 3) fail_line("expected 'element <name> <count>'", line);
    Element e;
    e.name = std::string(w[1]);
    const char* end = w[2].data() + w[2].size();
    const auto [ptr, ec] = std::from_chars(w[2].data(), end, e.count);
    if (ec != std::errc() || ptr != end)
      fail_line("element count " + quote(w[2]) + " is not a non-negative integer below 2^64", line);
    header_.elements.push_back(std::move(e));
  }

  void handle_property(const std::vector<std::string_view>& w, std::string_view line) {
    if (header_.elements.empty()) fail_line("property before any element", line);
    Property p;
    if (w.size() == 5 && w[1] == "list") {
      p = {std::string(w[4]), std::string(w[3]), true};
    } else if (w.size() == 3 && w[1] != "list") {
      p = {std::string(w[2]), std::string(w[1]), false};
    } else {
      fail_line("expected 'property <type> <name>' or 'property list <type> <type> <name>'", line);
    }
    header_.elements.back().properties.push_back(std::move(p));
  }

  const fs::path& path_;
  std::string_view text_;
  bool whole_file_;
  std::size_t pos_ = 0;
  int line_no_ = 0;
  bool format_seen_ = false;
  Header header_;
};

// The vertex element, after checking that no other element carries data.
const Element& vertex_element(const fs::path& path, const Header& h) {
  const Element* vertex = nullptr;
  for (const Element& e : h.elements) {
    if (e.name == "vertex") {
      if (vertex) fail(path, "more than one vertex element");
      vertex = &e;
    } else if (e.count > 0) {
      fail(path, "element '" + e.name + "' has " + std::to_string(e.count) +
                     " entries; only a vertex element is supported (other elements with data "
                     "would be dropped or could not be skipped)");
    }
  }
  if (!vertex) fail(path, "no vertex element");
  return *vertex;
}

void check_property_types(const fs::path& path, const Element& vertex) {
  std::set<std::string> seen;
  for (const Property& p : vertex.properties) {
    if (p.is_list) fail(path, "vertex property '" + p.name + "' is a list; only float properties are supported");
    if (p.type != "float" && p.type != "float32")
      fail(path, "vertex property '" + p.name + "' has type '" + p.type + "'; only float (float32) is supported");
    if (!seen.insert(p.name).second) fail(path, "duplicate vertex property '" + p.name + "'");
  }
}

int sh_degree_from_properties(const fs::path& path, const Element& vertex) {
  const auto count = std::count_if(vertex.properties.begin(), vertex.properties.end(),
                                   [](const Property& p) { return p.name.starts_with("f_rest_"); });
  for (int degree = 0; degree <= 3; ++degree)
    if (count == 3 * (sh_coeff_count(degree) - 1)) return degree;
  fail(path, "vertex element has " + std::to_string(count) +
                 " f_rest properties; expected 0, 9, 24 or 45 (SH degree 0, 1, 2 or 3)");
}

// Where one file property goes in the GaussianSet; read and ignored when column is null
// (normals).
struct Target {
  const Column* column = nullptr;
  std::string name;
};

std::vector<Target> map_properties(const fs::path& path, const Element& vertex, const std::vector<Column>& cols) {
  std::set<std::string> present;
  for (const Property& p : vertex.properties) present.insert(p.name);
  for (const Column& c : cols)
    if (c.field != Field::Normal && !present.count(c.name))
      fail(path, "missing required vertex property '" + c.name + "'");

  std::vector<Target> targets;
  for (const Property& p : vertex.properties) {
    const auto it = std::find_if(cols.begin(), cols.end(), [&](const Column& c) { return c.name == p.name; });
    if (it == cols.end()) fail(path, "unknown vertex property '" + p.name + "' (refusing to drop its data)");
    targets.push_back({it->field == Field::Normal ? nullptr : &*it, p.name});
  }
  return targets;
}

// Checks the body holds exactly n records, before anything is allocated for them.
void check_body_size(const fs::path& path, std::uint64_t n, std::uint64_t record, std::uint64_t body) {
  if (n > body / record)
    fail(path, "truncated: the header declares " + std::to_string(n) + " vertices of " + std::to_string(record) +
                   " bytes but only " + std::to_string(body) + " bytes follow the header (room for " +
                   std::to_string(body / record) + ")");
  if (body > n * record)
    fail(path, std::to_string(body - n * record) + " trailing bytes after the last of " + std::to_string(n) +
                   " vertex records");
}

void decode_records(const fs::path& path, std::istream& in, const std::vector<Target>& targets, GaussianSet& g) {
  // Resolve each property to its destination once: Gaussian i goes to base[i * stride + offset].
  struct Sink {
    float* base;  // null: read and ignored (normals)
    std::size_t stride, offset;
  };
  std::vector<Sink> sinks;
  for (const Target& t : targets) {
    if (!t.column) {
      sinks.push_back({nullptr, 0, 0});
      continue;
    }
    const Field f = t.column->field;
    sinks.push_back({array_of(g, f)->data(), static_cast<std::size_t>(stride_of(f, g.sh_degree)),
                     static_cast<std::size_t>(t.column->offset)});
  }

  const std::size_t n = g.size(), record = 4 * targets.size();
  const std::size_t per_chunk = std::max<std::size_t>(1, kChunkBytes / record);
  std::vector<unsigned char> buf(std::min(n, per_chunk) * record);
  for (std::size_t first = 0; first < n; first += per_chunk) {
    const std::size_t count = std::min(per_chunk, n - first);
    if (!in.read(reinterpret_cast<char*>(buf.data()), static_cast<std::streamsize>(count * record)))
      fail(path, "truncated: read failed at vertex " + std::to_string(first) + " (file changed while reading?)");
    const unsigned char* rec = buf.data();
    for (std::size_t i = first; i < first + count; ++i) {
      for (std::size_t p = 0; p < sinks.size(); ++p, rec += 4) {
        const Sink& s = sinks[p];
        if (!s.base) continue;
        const float v = load_le_float(rec);
        if (!std::isfinite(v))
          fail(path, "vertex " + std::to_string(i) + " property '" + targets[p].name + "' is " + describe_nonfinite(v));
        s.base[i * s.stride + s.offset] = v;
      }
    }
  }
}

}  // namespace

GaussianSet read_gaussian_ply(const fs::path& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) fail(path, "file does not exist");
  if (ec) fail(path, "cannot access: " + ec.message());
  if (!fs::is_regular_file(status)) fail(path, "not a regular file");
  const std::uintmax_t file_size = fs::file_size(path, ec);
  if (ec) fail(path, "cannot get the file size: " + ec.message());

  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, "cannot open for reading: " + errno_text());
  std::string prefix(static_cast<std::size_t>(std::min<std::uintmax_t>(file_size, kMaxHeaderBytes)), '\0');
  if (!in.read(prefix.data(), static_cast<std::streamsize>(prefix.size())))
    fail(path, "cannot read the header: " + errno_text());

  const Header header = HeaderParser(path, prefix, file_size <= kMaxHeaderBytes).parse();
  const Element& vertex = vertex_element(path, header);
  check_property_types(path, vertex);
  GaussianSet g;
  g.sh_degree = sh_degree_from_properties(path, vertex);
  const std::vector<Column> cols = standard_columns(g.sh_degree);
  const std::vector<Target> targets = map_properties(path, vertex, cols);
  check_body_size(path, vertex.count, 4 * targets.size(), file_size - header.bytes);

  g.resize(static_cast<std::size_t>(vertex.count));
  in.seekg(static_cast<std::streamoff>(header.bytes));
  decode_records(path, in, targets, g);
  return g;
}

}  // namespace desplat
