// SPDX-License-Identifier: LGPL-2.1-or-later
// Calibration files without cv::FileStorage: each format goes through its own maintained
// parser (libyaml's event API, libxml2 with neither entities nor network, nlohmann-json)
// into a small tree of the few entries a calibration needs; everything else in the file
// is skipped without being stored. The tree is then checked entry by entry.
#include "calibration_file.hpp"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cfloat>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <sys/stat.h>

#include <libxml/parser.h>
#include <libxml/tree.h>
#include <yaml.h>
#include <nlohmann/json.hpp>

namespace lftag::detail {
namespace {

[[noreturn]] void fail(const std::string& what) { throw std::runtime_error(what); }

// Text from the file, for a message: quoted, at most 40 bytes, unprintable bytes escaped.
std::string excerpt(std::string_view s) {
  std::string out = "'";
  std::size_t n = 0;
  for (const unsigned char c : s) {
    if (++n > 40) {
      out += "...";
      break;
    }
    if (c >= 0x20 && c < 0x7f) {
      out += char(c);
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      out += hex;
    }
  }
  return out + "'";
}

// A set of bytes, and the first byte of `text` from `from` that is (or is not) in it: a
// loop over a table, several times faster than string_view's find_first_of, which the
// passes over whole files below would otherwise spend most of their time in.
struct ByteSet {
  bool has[256] = {};
  constexpr explicit ByteSet(const char* bytes) {
    for (; *bytes; ++bytes) has[static_cast<unsigned char>(*bytes)] = true;
  }
};

std::size_t find_in(std::string_view text, std::size_t from, const ByteSet& set, bool in = true) {
  for (; from < text.size(); ++from)
    if (set.has[static_cast<unsigned char>(text[from])] == in) return from;
  return std::string_view::npos;
}

// Whether `text` holds `needle`: Horspool's search skips ahead by the needle's length,
// where string_view::find stops at every '<' of a file of a million tags.
bool contains(std::string_view text, std::string_view needle) {
  return std::search(text.begin(), text.end(), std::boyer_moore_horspool_searcher(needle.begin(), needle.end())) !=
         text.end();
}

const std::string kDepthError = "it nests deeper than " + std::to_string(kMaxCalibrationDepth) +
                                " levels; a calibration file is a flat list of entries with matrices in them";

std::string nodes_error(const char* nodes) {
  return "it has more than " + std::to_string(kMaxCalibrationNodes) + " " + nodes +
         "; a calibration file is a short list of entries with matrices in them";
}

// ---------------------------------------------------------------------------
// The entries a calibration needs, as read from any of the formats.

struct Value {
  enum class Kind { scalar, sequence, mapping };
  Kind kind = Kind::scalar;
  std::string text;        // scalar
  bool is_string = false;  // a quoted YAML scalar, a JSON string, true, false or null: not a number
  std::string tag;         // YAML tag, XML or JSON type_id
  std::vector<std::pair<std::string, Value>> items;  // sequence (keys empty) or mapping
};

const char* kind_name(const Value& v) {
  switch (v.kind) {
    case Value::Kind::scalar: return "a single value";
    case Value::Kind::sequence: return "a list";
    case Value::Kind::mapping: return "a mapping";
  }
  return "";
}

bool wanted(std::string_view key) {
  return key == "camera_matrix" || key == "cameraMatrix" || key == "distortion_coefficients" || key == "distCoeffs" ||
         key == "image_width" || key == "image_height";
}

class Entries {
 public:
  void add(const std::string& key, Value v) {
    if (!values_.emplace(key, std::move(v)).second) fail("'" + key + "' appears twice");
  }
  const Value* find(const std::string& key) const {
    const auto it = values_.find(key);
    return it == values_.end() ? nullptr : &it->second;
  }

 private:
  std::map<std::string, Value> values_;
};

// Bounds the size of an entry while it is read, before anything is stored.
class Budget {
 public:
  explicit Budget(std::string key) : key_(std::move(key)) {}
  void take() {
    if (--left_ < 0)
      fail("'" + key_ + "' has more than " + std::to_string(kMaxEntryValues) +
           " values; a camera matrix has 9 and a distortion at most 8");
  }

 private:
  std::string key_;
  int left_ = kMaxEntryValues;
};

// ---------------------------------------------------------------------------
// YAML (libyaml events)

class YamlEvents {
 public:
  explicit YamlEvents(std::string_view text) {
    if (!yaml_parser_initialize(&parser_)) fail("out of memory");
    yaml_parser_set_input_string(&parser_, reinterpret_cast<const unsigned char*>(text.data()), text.size());
  }
  ~YamlEvents() {
    if (has_event_) yaml_event_delete(&event_);
    yaml_parser_delete(&parser_);
  }
  YamlEvents(const YamlEvents&) = delete;
  YamlEvents& operator=(const YamlEvents&) = delete;

  const yaml_event_t& current() const { return event_; }

  const yaml_event_t& next() {
    if (has_event_) yaml_event_delete(&event_);
    has_event_ = false;
    if (!yaml_parser_parse(&parser_, &event_)) {
      std::string what = "it is not valid YAML: line " + std::to_string(parser_.problem_mark.line + 1) + ", column " +
                         std::to_string(parser_.problem_mark.column + 1) + ": " +
                         (parser_.problem ? parser_.problem : "out of memory");
      if (parser_.context) what += std::string(" ") + parser_.context;
      fail(what);
    }
    has_event_ = true;
    // Each node costs libyaml an event or two: their number bounds the time.
    if ((event_.type == YAML_SCALAR_EVENT || event_.type == YAML_SEQUENCE_START_EVENT ||
         event_.type == YAML_MAPPING_START_EVENT) &&
        ++nodes_ > kMaxCalibrationNodes)
      fail(nodes_error("YAML nodes (keys, values, lists and mappings)"));
    // An alias repeats a subtree: a few bytes can stand for billions of nodes.
    const yaml_char_t* anchor = nullptr;
    switch (event_.type) {
      case YAML_ALIAS_EVENT:
        fail("it uses a YAML alias (*" + std::string(reinterpret_cast<const char*>(event_.data.alias.anchor)) +
             "); aliases and anchors are not supported in calibration files");
      case YAML_SCALAR_EVENT: anchor = event_.data.scalar.anchor; break;
      case YAML_SEQUENCE_START_EVENT: anchor = event_.data.sequence_start.anchor; break;
      case YAML_MAPPING_START_EVENT: anchor = event_.data.mapping_start.anchor; break;
      default: break;
    }
    if (anchor)
      fail("it uses a YAML anchor (&" + std::string(reinterpret_cast<const char*>(anchor)) +
           "); aliases and anchors are not supported in calibration files");
    return event_;
  }

 private:
  yaml_parser_t parser_{};
  yaml_event_t event_{};
  bool has_event_ = false;
  int nodes_ = 0;
};

std::string scalar_text(const yaml_event_t& e) {
  return {reinterpret_cast<const char*>(e.data.scalar.value), e.data.scalar.length};
}

// The value that starts with the current event, `depth` levels down.
Value build_yaml(YamlEvents& events, int depth, Budget& budget) {
  const yaml_event_t& e = events.current();
  Value v;
  if (e.type == YAML_SCALAR_EVENT) {
    budget.take();
    v.text = scalar_text(e);
    v.is_string = e.data.scalar.style != YAML_PLAIN_SCALAR_STYLE || e.data.scalar.tag != nullptr;
    return v;
  }
  if (depth > kMaxCalibrationDepth) fail(kDepthError);
  const bool mapping = e.type == YAML_MAPPING_START_EVENT;
  const yaml_char_t* tag = mapping ? e.data.mapping_start.tag : e.data.sequence_start.tag;
  if (tag) v.tag = reinterpret_cast<const char*>(tag);
  v.kind = mapping ? Value::Kind::mapping : Value::Kind::sequence;
  for (;;) {
    const yaml_event_t& item = events.next();
    if (item.type == YAML_MAPPING_END_EVENT || item.type == YAML_SEQUENCE_END_EVENT) return v;
    std::string key;
    if (mapping) {
      if (item.type != YAML_SCALAR_EVENT) fail("a key inside an entry is not a name");
      budget.take();
      key = scalar_text(item);
      events.next();
    }
    Value child = build_yaml(events, depth + 1, budget);
    v.items.emplace_back(std::move(key), std::move(child));
  }
}

// Passes over the value that starts with the current event, keeping nothing.
void skip_yaml(YamlEvents& events, int depth) {
  int level = 0;
  for (;;) {
    const yaml_event_type_t type = events.current().type;
    if (type == YAML_MAPPING_START_EVENT || type == YAML_SEQUENCE_START_EVENT) {
      if (depth + level > kMaxCalibrationDepth) fail(kDepthError);
      ++level;
    } else if (type == YAML_MAPPING_END_EVENT || type == YAML_SEQUENCE_END_EVENT) {
      --level;
    }
    if (level == 0) return;
    events.next();
  }
}

Entries read_yaml(std::string_view text) {
  // OpenCV starts its YAML with "%YAML:1.0", which YAML itself does not allow (a directive
  // is "%YAML 1.1"): that first line becomes a comment; the offsets stay.
  std::string source(text);
  if (source.rfind("%YAML:", 0) == 0) {
    const std::size_t end = std::min(source.find('\n'), source.size());
    std::size_t i = 6;
    const std::size_t digits = i;
    while (i < end && (std::isdigit(static_cast<unsigned char>(source[i])) || source[i] == '.')) ++i;
    const bool version = i > digits && source[digits] == '1';
    while (i < end && (source[i] == ' ' || source[i] == '\t' || source[i] == '\r')) ++i;
    if (!version || i != end)
      fail("its first line " + excerpt(source.substr(0, end)) + " is not an OpenCV YAML header (expected %YAML:1.0)");
    source[0] = '#';
  }
  // libyaml checks each %TAG directive against all before it, before the first event:
  // 60,000 of them in 1 MiB took 9 s.
  int directives = 0;
  for (std::size_t i = source.find('%'); i != std::string::npos; i = source.find('%', i + 1))
    if ((i == 0 || source[i - 1] == '\n') && ++directives > kMaxYamlDirectives)
      fail("it has more than " + std::to_string(kMaxYamlDirectives) +
           " lines starting with '%' (YAML directives); an OpenCV YAML file has one, %YAML:1.0");
  YamlEvents events(source);
  events.next();  // stream start
  if (events.next().type == YAML_STREAM_END_EVENT)
    fail("it is empty, expected an OpenCV calibration with camera_matrix and distortion_coefficients");
  // document start
  const yaml_event_t& root = events.next();
  if (root.type != YAML_MAPPING_START_EVENT)
    fail("its top level is not a mapping of named entries (expected 'camera_matrix: !!opencv-matrix' ...)");
  Entries entries;
  for (;;) {
    const yaml_event_t& key_event = events.next();
    if (key_event.type == YAML_MAPPING_END_EVENT) break;
    if (key_event.type != YAML_SCALAR_EVENT) fail("a top-level key is not a name");
    const std::string key = scalar_text(key_event);
    events.next();
    if (wanted(key)) {
      Budget budget(key);
      entries.add(key, build_yaml(events, 2, budget));
    } else {
      skip_yaml(events, 2);
    }
  }
  events.next();  // document end
  if (events.next().type != YAML_STREAM_END_EVENT) fail("it holds more than one YAML document, expected one");
  return entries;
}

// ---------------------------------------------------------------------------
// XML (libxml2)

constexpr ByteSet kBlank(" \t\r\n");

bool blank(std::string_view s) { return find_in(s, 0, kBlank, false) == std::string_view::npos; }

std::string name_of(const xmlNode* node) { return reinterpret_cast<const char*>(node->name); }

void check_xml_depth(const xmlNode* node, int depth) {
  if (depth > kMaxCalibrationDepth) fail(kDepthError);
  for (const xmlNode* c = node->children; c; c = c->next)
    if (c->type == XML_ELEMENT_NODE) check_xml_depth(c, depth + 1);
}

// A linear pass over the XML before libxml2 parses it. libxml2 compares each attribute of
// an element with all those before it (150,000 attributes on one element, 1 MiB, did not
// finish in a minute; 75,000 namespace declarations took 1.2 s), and every node costs it
// an allocation.
// This pass counts elements, attributes, comments, processing instructions, CDATA
// sections and references, and the nesting. What it cannot follow is not well-formed XML
// and is refused here: libxml2 goes on parsing past an error (only without building the
// tree), so it must not be handed a file that this pass has not bounded.
void scan_xml(std::string_view text) {
  int nodes = 0, depth = 0;
  auto count = [&](std::size_t n) {
    if ((nodes += int(std::min<std::size_t>(n, kMaxCalibrationNodes + 1))) > kMaxCalibrationNodes)
      fail(nodes_error("XML elements, attributes, comments and references"));
  };
  auto past = [&](std::size_t from, std::string_view end, const char* what) {
    const std::size_t at = text.find(end, from);
    if (at == std::string_view::npos) fail(std::string("it is not valid XML: ") + what + " is not closed");
    return at + end.size();
  };
  auto starts = [&](std::size_t at, std::string_view s) { return text.compare(at, s.size(), s) == 0; };
  static constexpr ByteSet markup("<&"), tag("\"'=<>"), name_end(" \t\r\n/>"), double_quoted("\"<"),
      single_quoted("'<");
  for (std::size_t i = find_in(text, 0, markup); i != std::string_view::npos; i = find_in(text, i, markup)) {
    if (text[i] == '&') {  // an entity or character reference
      count(1);
      ++i;
    } else if (starts(i, "<!--")) {
      count(1);
      i = past(i + 4, "-->", "a comment");
    } else if (starts(i, "<![CDATA[")) {
      count(1);
      i = past(i + 9, "]]>", "a CDATA section");
    } else if (starts(i, "<?")) {
      count(1);
      i = past(i + 2, "?>", "a processing instruction");
    } else if (starts(i, "<!")) {  // <!DOCTYPE and <!ENTITY are refused before this pass
      fail("it is not valid XML: it has a declaration (<!) that is not a comment or CDATA section");
    } else if (starts(i, "</")) {
      depth = std::max(depth - 1, 0);
      i = past(i + 2, ">", "an end tag");
    } else {
      // A start tag: name, then attributes name="value" or name='value', whose values hold
      // no '<' (and may hold '>', '=' and references).
      const std::size_t end = std::min(find_in(text, i + 1, name_end), text.size());
      const std::string name = "<" + std::string(text.substr(i + 1, std::min<std::size_t>(end - i - 1, 64))) + ">";
      count(1);
      int attributes = 0;
      std::size_t j = i + 1;
      for (;;) {
        j = find_in(text, j, tag);
        if (j == std::string_view::npos || text[j] == '<')
          fail("it is not valid XML: the start tag " + excerpt(name) + " is not closed");
        if (text[j] == '>') break;
        if (text[j] == '=') {
          if (++attributes > kMaxXmlAttributes)
            fail("the XML element " + excerpt(name) + " has more than " + std::to_string(kMaxXmlAttributes) +
                 " attributes; OpenCV writes at most one (type_id)");
          count(1);
          ++j;
          continue;
        }
        const std::size_t close = find_in(text, j + 1, text[j] == '"' ? double_quoted : single_quoted);
        if (close == std::string_view::npos || text[close] == '<')
          fail("it is not valid XML: an attribute value of " + excerpt(name) + " is not closed or holds '<'");
        count(std::size_t(std::count(text.begin() + j, text.begin() + close, '&')));
        j = close + 1;
      }
      if (text[j - 1] != '/' && ++depth > kMaxCalibrationDepth) fail(kDepthError);
      i = j + 1;
    }
  }
}

Value build_xml(const xmlNode* node, Budget& budget) {
  Value v;
  if (xmlChar* type = xmlGetNoNsProp(node, reinterpret_cast<const xmlChar*>("type_id"))) {
    v.tag = reinterpret_cast<const char*>(type);
    xmlFree(type);
  }
  bool elements = false;
  std::string text;
  for (const xmlNode* c = node->children; c; c = c->next) {
    switch (c->type) {
      case XML_ELEMENT_NODE: elements = true; break;
      case XML_TEXT_NODE:
      case XML_CDATA_SECTION_NODE:
        if (c->content) text += reinterpret_cast<const char*>(c->content);
        break;
      case XML_COMMENT_NODE:
      case XML_PI_NODE: break;
      default: fail("<" + name_of(node) + "> holds XML other than elements and text (an entity reference?)");
    }
  }
  if (elements) {
    if (!blank(text)) fail("<" + name_of(node) + "> mixes text and elements");
    v.kind = Value::Kind::mapping;
    bool all_items = true;  // OpenCV writes the items of a list of structures as <_>
    for (const xmlNode* c = node->children; c; c = c->next) {
      if (c->type != XML_ELEMENT_NODE) continue;
      budget.take();
      v.items.emplace_back(name_of(c), build_xml(c, budget));
      all_items = all_items && v.items.back().first == "_";
    }
    if (all_items) {
      v.kind = Value::Kind::sequence;
      for (auto& item : v.items) item.first.clear();
    }
    return v;
  }
  // Text: one value, or a list of values separated by white space (matrix data).
  std::vector<std::string_view> tokens;
  const std::string_view all(text);
  for (std::size_t i = find_in(all, 0, kBlank, false); i != std::string_view::npos;) {
    const std::size_t end = std::min(find_in(all, i, kBlank), all.size());
    budget.take();
    tokens.push_back(all.substr(i, end - i));
    i = find_in(all, end, kBlank, false);
  }
  if (tokens.size() == 1) {
    v.text = std::string(tokens[0]);
  } else if (tokens.size() > 1) {
    v.kind = Value::Kind::sequence;
    for (std::string_view t : tokens) {
      Value item;
      item.text = std::string(t);
      v.items.emplace_back(std::string(), std::move(item));
    }
  }
  return v;
}

Entries read_xml(std::string_view text) {
  // No document type, so no entity can be declared (no "billion laughs") and no external
  // DTD loaded; the bytes are read as UTF-8 whatever they declare, so this test cannot be
  // dodged by another encoding (UTF-16 and UTF-32 have NUL bytes, refused before).
  if (contains(text, "<!DOCTYPE") || contains(text, "<!ENTITY"))
    fail(
        "it has an XML document type or entity declaration (<!DOCTYPE, <!ENTITY), which calibration files "
        "may not have");
  scan_xml(text);
  static std::once_flag init;
  std::call_once(init, [] { xmlInitParser(); });
  const std::unique_ptr<xmlParserCtxt, void (*)(xmlParserCtxtPtr)> context(xmlNewParserCtxt(), xmlFreeParserCtxt);
  if (!context) fail("out of memory");
  // Without XML_PARSE_NOENT entities are not substituted, without XML_PARSE_DTDLOAD no
  // external subset is read, XML_PARSE_NONET forbids the network, and without
  // XML_PARSE_HUGE libxml2 keeps its default limits (depth, text and name lengths).
  const int options = XML_PARSE_NONET | XML_PARSE_NOERROR | XML_PARSE_NOWARNING | XML_PARSE_IGNORE_ENC;
  const std::unique_ptr<xmlDoc, void (*)(xmlDocPtr)> doc(
      xmlCtxtReadMemory(context.get(), text.data(), int(text.size()), nullptr, "UTF-8", options), xmlFreeDoc);
  if (!doc) {
    const xmlError* error = xmlCtxtGetLastError(context.get());
    std::string message = error && error->message ? error->message : "syntax error";
    while (!message.empty() && std::isspace(static_cast<unsigned char>(message.back()))) message.pop_back();
    fail("it is not valid XML: line " + std::to_string(error ? error->line : 0) + ": " + message);
  }
  if (doc->intSubset || doc->extSubset) fail("it has an XML document type, which calibration files may not have");
  const xmlNode* root = xmlDocGetRootElement(doc.get());
  if (!root || name_of(root) != "opencv_storage")
    fail("its XML root element is " + (root ? "<" + name_of(root) + ">" : std::string("missing")) +
         ", expected <opencv_storage>");
  check_xml_depth(root, 1);
  Entries entries;
  for (const xmlNode* c = root->children; c; c = c->next) {
    if (c->type == XML_ENTITY_REF_NODE) fail("it has an XML entity reference, which calibration files may not have");
    if (c->type != XML_ELEMENT_NODE || !wanted(name_of(c))) continue;
    Budget budget(name_of(c));
    entries.add(name_of(c), build_xml(c, budget));
  }
  return entries;
}

// ---------------------------------------------------------------------------
// JSON (nlohmann-json)

std::string number_text(double d) {
  if (!std::isfinite(d)) return d != d ? "nan" : d > 0 ? "inf" : "-inf";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, d);  // shortest round trip
  return std::string(buf, r.ptr);
}

Value build_json(const nlohmann::json& j, Budget& budget) {
  Value v;
  if (j.is_object()) {
    v.kind = Value::Kind::mapping;
    for (const auto& [key, item] : j.items()) {
      budget.take();
      if (key == "type_id") {
        if (!item.is_string()) fail("a 'type_id' is not a string");
        v.tag = item.get<std::string>();
        continue;
      }
      v.items.emplace_back(key, build_json(item, budget));
    }
  } else if (j.is_array()) {
    v.kind = Value::Kind::sequence;
    for (const auto& item : j) v.items.emplace_back(std::string(), build_json(item, budget));
  } else {
    budget.take();
    if (j.is_number_float()) {
      v.text = number_text(j.get<double>());
    } else if (j.is_number()) {
      v.text = j.dump();
    } else {
      v.text = j.is_string() ? j.get<std::string>() : j.dump();
      v.is_string = true;
    }
  }
  return v;
}

// A linear pass over the JSON before nlohmann-json parses it into a tree: bounds the
// values and keys (each costs an allocation), the nesting, and the length of numbers (one
// of a million digits costs strtod milliseconds). The entries that are read are held to
// their Budget here already, with the same count as build_json (keys and scalars), so
// that the tree is never larger than the reading would allow.
void scan_json(std::string_view text) {
  int nodes = 0, depth = 0;
  std::optional<Budget> entry;  // inside a top-level entry that is read
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '"') {  // a string, to the first quote not escaped
      const std::size_t first = i + 1;
      for (++i; i < text.size() && text[i] != '"'; ++i)
        if (text[i] == '\\') ++i;
      const std::size_t next = find_in(text, i + 1, kBlank, false);
      const bool key = next != std::string_view::npos && text[next] == ':';
      if (depth == 1 && key) {
        const std::string name(text.substr(first, std::min(i, text.size()) - first));
        entry.reset();
        if (wanted(name)) entry.emplace(name);
      } else if (entry) {
        entry->take();
      }
    } else if (c == '-' || (c >= '0' && c <= '9')) {
      static constexpr ByteSet number("0123456789+-.eE");
      const std::size_t end = std::min(find_in(text, i, number, false), text.size());
      if (end - i > kMaxNumberChars)
        fail("it has a number of more than " + std::to_string(kMaxNumberChars) + " characters, " +
             excerpt(text.substr(i, end - i)));
      if (entry) entry->take();
      i = end - 1;
    } else if (c >= 'a' && c <= 'z') {  // true, false, null
      if (entry) entry->take();
      static constexpr ByteSet letters("abcdefghijklmnopqrstuvwxyz");
      i = std::min(find_in(text, i, letters, false), text.size()) - 1;
    } else if (c == '}' || c == ']') {
      if (--depth < 1) entry.reset();
    } else if (c == '{' || c == '[' || c == ',' || c == ':') {
      if ((c == '{' || c == '[') && ++depth > kMaxCalibrationDepth) fail(kDepthError);
      if (c == ',' && depth == 1) entry.reset();
      if (++nodes > kMaxCalibrationNodes) fail(nodes_error("JSON values and keys"));
    }
  }
}

Entries read_json(std::string_view text) {
  scan_json(text);
  nlohmann::json doc;
  try {
    // The parser keeps its own stack on the heap; the callback bounds its depth.
    doc = nlohmann::json::parse(text.begin(), text.end(),
                                [](int depth, nlohmann::json::parse_event_t event, nlohmann::json&) {
                                  if ((event == nlohmann::json::parse_event_t::object_start ||
                                       event == nlohmann::json::parse_event_t::array_start) &&
                                      depth + 1 > kMaxCalibrationDepth)
                                    fail(kDepthError);
                                  return true;
                                });
  } catch (const nlohmann::json::exception& e) {
    std::string what = e.what();
    if (const std::size_t bracket = what.find("] ");
        what.rfind("[json.exception", 0) == 0 && bracket != std::string::npos)
      what.erase(0, bracket + 2);
    fail("it is not valid JSON: " + what);
  }
  if (!doc.is_object()) fail("its top level is not a JSON object of named entries");
  Entries entries;
  for (const auto& [key, value] : doc.items()) {
    if (!wanted(key)) continue;
    Budget budget(key);
    entries.add(key, build_json(value, budget));
  }
  return entries;
}

// ---------------------------------------------------------------------------
// The camera from the entries

// A number, or an error saying what `what` is and what it should be.
double number(const Value& v, const std::string& what) {
  if (v.kind != Value::Kind::scalar) fail(what + " is " + kind_name(v) + ", expected a number");
  const std::string& s = v.text;
  if (s.size() > kMaxNumberChars)
    fail(what + " is " + excerpt(s) + ", expected a number (of at most " + std::to_string(kMaxNumberChars) +
         " characters)");
  std::string lower;
  for (char c : s) lower += char(std::tolower(static_cast<unsigned char>(c)));
  if (!v.is_string && (lower == ".nan" || lower == ".inf" || lower == "-.inf" || lower == "+.inf"))
    fail(what + " is " + excerpt(s) + ", expected a finite number");
  double d = 0;
  const char* first = s.data() + (!s.empty() && s[0] == '+' ? 1 : 0);
  const char* last = s.data() + s.size();
  const auto [end, error] = std::from_chars(first, last, d);
  if (v.is_string || s.empty() || (error != std::errc() && error != std::errc::result_out_of_range) || end != last)
    fail(what + " is " + excerpt(s) + ", expected a number");
  if (error == std::errc::result_out_of_range || !std::isfinite(d))
    fail(what + " is " + excerpt(s) + ", expected a finite number within the range of a double");
  return d;
}

// A whole number in [lo, hi].
long long whole(const Value& v, const std::string& what, double lo, double hi, const std::string& unit = "") {
  const double d = number(v, what);
  if (!(d == std::floor(d) && d >= lo && d <= hi))
    fail(what + " is " + excerpt(v.text) + ", expected a whole number" + unit + " from " + number_text(lo) + " to " +
         number_text(hi));
  return static_cast<long long>(d);
}

struct Matrix {
  long long rows = 0, cols = 0;
  std::vector<double> data;
};

// An OpenCV matrix: a mapping with rows, cols, dt and data. `check_shape` refuses a shape
// before any of the data is read.
template <typename CheckShape>
Matrix matrix(const std::string& key, const Value& v, CheckShape check_shape) {
  const std::string name = "'" + key + "'";
  const std::string expected = ", expected an OpenCV matrix (type opencv-matrix with rows, cols, dt and data)";
  if (v.kind != Value::Kind::mapping) fail(name + " is " + kind_name(v) + expected);
  if (!v.tag.empty() && (v.tag.size() < 13 || v.tag.compare(v.tag.size() - 13, 13, "opencv-matrix") != 0))
    fail(name + " has the type " + excerpt(v.tag) + expected);
  auto field = [&](const char* f) -> const Value& {
    const Value* found = nullptr;
    for (const auto& [k, item] : v.items) {
      if (k != f) continue;
      if (found) fail(name + " has two '" + f + "'");
      found = &item;
    }
    if (!found) fail(name + " has no '" + f + "'" + expected);
    return *found;
  };
  const double max_side = 9007199254740992.0;  // 2^53
  Matrix m;
  m.rows = whole(field("rows"), name + " rows", 1, max_side);
  m.cols = whole(field("cols"), name + " cols", 1, max_side);
  check_shape(m.rows, m.cols);
  const Value& dt = field("dt");
  const std::string type = dt.kind == Value::Kind::scalar ? dt.text : std::string();
  if (type.size() != 1 || std::string("ucwsifd").find(type[0]) == std::string::npos)
    fail(name + " dt is " + (dt.kind == Value::Kind::scalar ? excerpt(dt.text) : std::string(kind_name(dt))) +
         ", expected d or f (one channel of numbers)");
  const Value& data = field("data");
  const std::size_t count = std::size_t(m.rows * m.cols);
  if (data.kind == Value::Kind::mapping || (data.kind == Value::Kind::scalar && count != 1) ||
      (data.kind == Value::Kind::sequence && data.items.size() != count))
    fail(name + " data is " +
         (data.kind == Value::Kind::sequence ? "a list of " + std::to_string(data.items.size()) + " values"
                                             : std::string(kind_name(data))) +
         ", expected " + std::to_string(count) + " numbers (" + std::to_string(m.rows) + "x" + std::to_string(m.cols) +
         ")");
  for (std::size_t i = 0; i < count; ++i) {
    const Value& item = data.kind == Value::Kind::scalar ? data : data.items[i].second;
    const std::string what = name + " data item " + std::to_string(i + 1);
    double d = number(item, what);
    if (type == "f") {
      if (std::abs(d) > FLT_MAX) fail(what + " is " + excerpt(item.text) + ", out of the range of dt f (float)");
      d = double(float(d));
    } else if (type != "d" && d != std::floor(d)) {
      fail(what + " is " + excerpt(item.text) + ", expected a whole number for dt " + type);
    }
    m.data.push_back(d);
  }
  return m;
}

// The first of `keys` present in the file.
std::pair<std::string, const Value*> first_of(const Entries& entries, std::initializer_list<const char*> keys) {
  for (const char* key : keys)
    if (const Value* v = entries.find(key)) return {key, v};
  return {"", nullptr};
}

Camera to_camera(const Entries& entries) {
  Camera cam;
  // Named variables, not structured bindings: C++17 lambdas cannot capture those (clang).
  const auto k_entry = first_of(entries, {"camera_matrix", "cameraMatrix"});
  const std::string& k_key = k_entry.first;
  const Value* k_value = k_entry.second;
  if (!k_value)
    fail(
        "no 'camera_matrix' (or 'cameraMatrix') entry, expected an OpenCV calibration with camera_matrix and "
        "distortion_coefficients");
  const Matrix k = matrix(k_key, *k_value, [&](long long rows, long long cols) {
    if (rows != 3 || cols != 3)
      fail("the camera matrix '" + k_key + "' is " + std::to_string(rows) + "x" + std::to_string(cols) +
           ", expected 3x3");
  });
  const auto& a = k.data;
  cam.fx = a[0], cam.fy = a[4], cam.cx = a[2], cam.cy = a[5];
  // [fx s cx; 0 fy cy; 0 0 1], and the detector has no skew.
  const double tiny = 1e-9;
  if (std::abs(a[3]) > tiny || std::abs(a[6]) > tiny || std::abs(a[7]) > tiny || std::abs(a[8] - 1) > tiny ||
      std::abs(a[1]) > tiny * std::abs(a[0]))
    fail("the camera matrix '" + k_key + "' is not of the form [fx 0 cx; 0 fy cy; 0 0 1] (skew is not supported)");

  const auto d_entry = first_of(entries, {"distortion_coefficients", "distCoeffs"});
  const std::string& d_key = d_entry.first;
  const Value* d_value = d_entry.second;
  if (d_value) {
    const Matrix d = matrix(d_key, *d_value, [&](long long rows, long long cols) {
      const long long n = rows * cols;  // both at most 2^53: the product only matters when one is 1
      const std::string shape = std::to_string(rows) + "x" + std::to_string(cols);
      const std::string expected = "expected 4, 5 or 8 coefficients in one row or column (k1 k2 p1 p2 [k3 [k4 k5 k6]])";
      if (rows != 1 && cols != 1) fail("the distortion '" + d_key + "' is " + shape + ", " + expected);
      if (n == 12 || n == 14)
        fail("the distortion '" + d_key + "' has " + std::to_string(n) +
             " coefficients: the thin-prism (12) and tilted-sensor (14) models are not supported, " + expected);
      if (n != 4 && n != 5 && n != 8)
        fail("the distortion '" + d_key + "' has " + std::to_string(n) + " coefficients, " + expected);
    });
    cam.distortion = d.data;
  }
  const double max_size = Camera::kMaxImageSide;
  if (const Value* w = entries.find("image_width"))
    cam.width = int(whole(*w, "'image_width'", 0, max_size, " of pixels"));
  if (const Value* h = entries.find("image_height"))
    cam.height = int(whole(*h, "'image_height'", 0, max_size, " of pixels"));
  cam.calibrated = true;
  try {
    cam.validate();
  } catch (const std::invalid_argument& e) {
    fail(e.what());
  }
  return cam;
}

}  // namespace

std::string not_a_regular_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int error = errno;
    struct stat link {};
    if (error == ENOENT && ::lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode))
      return "is a symbolic link to a file that does not exist";
    if (error == ENOENT || error == ENOTDIR) return "does not exist";
    if (error == ELOOP) return "is a symbolic link loop";
    return std::string("cannot be reached (") + std::strerror(error) + ")";
  }
  if (S_ISREG(st.st_mode)) return "";
  if (S_ISDIR(st.st_mode)) return "is a directory";
  if (S_ISFIFO(st.st_mode)) return "is a FIFO";
  if (S_ISCHR(st.st_mode)) return "is a character device";
  if (S_ISBLK(st.st_mode)) return "is a block device";
  if (S_ISSOCK(st.st_mode)) return "is a socket";
  return "is not a regular file";
}

Camera read_calibration(std::string_view text) {
  if (text.size() > kMaxCalibrationBytes)
    fail("it is " + std::to_string(text.size()) + " bytes, more than the " + std::to_string(kMaxCalibrationBytes) +
         " (1 MiB) a calibration file may have");
  if (const std::size_t nul = text.find('\0'); nul != std::string_view::npos)
    fail("it has a NUL byte at offset " + std::to_string(nul) + ", expected text (OpenCV YAML, XML or JSON)");
  std::string_view body = text;
  if (body.rfind("\xEF\xBB\xBF", 0) == 0) body.remove_prefix(3);  // UTF-8 byte order mark
  const std::size_t first = body.find_first_not_of(" \t\r\n");
  if (first == std::string_view::npos)
    fail(
        "it is empty, expected an OpenCV calibration (YAML, XML or JSON) with camera_matrix and "
        "distortion_coefficients");
  const Entries entries = body[first] == '<' ? read_xml(text) : body[first] == '{' ? read_json(text) : read_yaml(text);
  return to_camera(entries);
}

}  // namespace lftag::detail
