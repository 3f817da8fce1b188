#include "rcal/transport/lcm_schema.hpp"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <map>
#include <optional>
#include <stdexcept>

namespace rcal::transport {
namespace {

// Encoded size of each LCM primitive; string is variable (0 here).
const std::map<std::string, int, std::less<>>& Primitives() {
  static const std::map<std::string, int, std::less<>> k = {
      {"int8_t", 1}, {"byte", 1},    {"boolean", 1}, {"int16_t", 2}, {"int32_t", 4},
      {"float", 4},  {"int64_t", 8}, {"double", 8},  {"string", 0}};
  return k;
}
bool IsPrimitive(std::string_view t) {
  return Primitives().count(t) > 0;
}
bool IsInteger(std::string_view t) {
  return t == "int8_t" || t == "int16_t" || t == "int32_t" || t == "int64_t";
}

// ---- parsing ----------------------------------------------------------------------------------

struct Token {
  std::string text;
  int line = 0;
};

// Identifiers (with '.' for package-qualified names), numbers (with sign, '.', exponent) and the
// single-character punctuation of the grammar; comments dropped.
std::vector<Token> Tokenize(std::string_view s, const std::string& source) {
  std::vector<Token> out;
  int line = 1;
  size_t i = 0;
  while (i < s.size()) {
    const char c = s[i];
    if (c == '\n') {
      ++line;
      ++i;
    } else if (std::isspace(static_cast<unsigned char>(c))) {
      ++i;
    } else if (s.compare(i, 2, "//") == 0) {
      while (i < s.size() && s[i] != '\n') ++i;
    } else if (s.compare(i, 2, "/*") == 0) {
      const size_t end = s.find("*/", i + 2);
      if (end == std::string_view::npos)
        throw std::runtime_error(source + ":" + std::to_string(line) + ": unterminated comment");
      line += static_cast<int>(
          std::count(s.begin() + static_cast<long>(i), s.begin() + static_cast<long>(end), '\n'));
      i = end + 2;
    } else if (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '+' ||
               c == '.') {
      size_t j = i + 1;
      while (j < s.size() && (std::isalnum(static_cast<unsigned char>(s[j])) || s[j] == '_' ||
                              s[j] == '.' || s[j] == '-' || s[j] == '+'))
        ++j;
      out.push_back({std::string(s.substr(i, j - i)), line});
      i = j;
    } else if (std::string_view("{}[];,=").find(c) != std::string_view::npos) {
      out.push_back({std::string(1, c), line});
      ++i;
    } else {
      throw std::runtime_error(source + ":" + std::to_string(line) + ": unexpected character '" +
                               std::string(1, c) + "'");
    }
  }
  return out;
}

class Parser {
 public:
  Parser(std::vector<Token> tokens, const std::string& source)
      : t_(std::move(tokens)), source_(source) {}

  std::vector<LcmStruct> File() {
    std::vector<LcmStruct> out;
    std::string package;
    while (!AtEnd()) {
      const std::string word = Next();
      if (word == "package") {
        package = Next();
        Expect(";");
      } else if (word == "struct") {
        out.push_back(Struct(package));
      } else {
        Fail("expected 'package' or 'struct', found '" + word + "'");
      }
    }
    return out;
  }

 private:
  LcmStruct Struct(const std::string& package) {
    LcmStruct s;
    s.package = package;
    s.name = Next();
    s.source = source_;
    Expect("{");
    while (Peek() != "}") {
      if (Peek() == "const") {  // constants are not on the wire
        while (Next() != ";") {
        }
        continue;
      }
      std::string type = Next();
      if (const size_t dot = type.rfind('.'); dot != std::string::npos) type = type.substr(dot + 1);
      do {
        LcmMember m;
        m.type = type;
        m.name = Next();
        if (!IsName(m.name)) Fail("'" + m.name + "' is not a member name");
        while (Peek() == "[") {
          Next();
          LcmDimension d;
          d.size = Next();
          int64_t n = 0;
          const auto [p, ec] = std::from_chars(d.size.data(), d.size.data() + d.size.size(), n);
          if (ec == std::errc() && p == d.size.data() + d.size.size()) {
            if (n < 0) Fail("negative dimension " + d.size);
            d.constant = n;
          } else {
            d.variable = true;
            const auto it = std::find_if(s.members.begin(), s.members.end(),
                                         [&](const LcmMember& e) { return e.name == d.size; });
            if (it == s.members.end() || !IsInteger(it->type) || !it->dimensions.empty())
              Fail("dimension '" + d.size + "' of " + m.name +
                   " is not an earlier integer member of " + s.name);
          }
          Expect("]");
          m.dimensions.push_back(std::move(d));
        }
        s.members.push_back(std::move(m));
      } while (Peek() == "," && !Next().empty());
      Expect(";");
    }
    Expect("}");
    return s;
  }

  static bool IsName(const std::string& w) {
    return !w.empty() && (std::isalpha(static_cast<unsigned char>(w[0])) || w[0] == '_') &&
           std::all_of(w.begin(), w.end(), [](char c) {
             return std::isalnum(static_cast<unsigned char>(c)) || c == '_';
           });
  }
  bool AtEnd() const { return i_ >= t_.size(); }
  const std::string& Peek() {
    if (AtEnd()) Fail("unexpected end of file");
    return t_[i_].text;
  }
  std::string Next() {
    Peek();
    return t_[i_++].text;
  }
  void Expect(const char* what) {
    const std::string w = Next();
    if (w != what) {
      --i_;
      Fail(std::string("expected '") + what + "', found '" + w + "'");
    }
  }
  [[noreturn]] void Fail(const std::string& why) const {
    const int line = t_.empty() ? 0 : t_[std::min(i_, t_.size() - 1)].line;
    throw std::runtime_error(source_ + ":" + std::to_string(line) + ": " + why);
  }

  std::vector<Token> t_;
  std::string source_;
  size_t i_ = 0;
};

// ---- lcm-gen's fingerprint ---------------------------------------------------------------------

// lcmgen.c: v = ((v << 8) ^ (v >> 55)) + c, on int64_t (arithmetic right shift), c a char.
int64_t HashUpdate(int64_t v, char c) {
  const auto shifted = static_cast<int64_t>(static_cast<uint64_t>(v) << 8);
  return static_cast<int64_t>(static_cast<uint64_t>(shifted ^ (v >> 55)) +
                              static_cast<uint64_t>(static_cast<int64_t>(c)));
}
int64_t HashString(int64_t v, const std::string& s) {
  v = HashUpdate(v, static_cast<char>(s.size()));
  for (char c : s) v = HashUpdate(v, c);
  return v;
}
// lcm_struct_hash: member names, primitive type names and dimensions (mode: 0 constant, 1
// variable, and the size as written); the struct's own name is left out on purpose.
int64_t StructHash(const LcmStruct& s) {
  int64_t v = 0x12345678;
  for (const auto& m : s.members) {
    v = HashString(v, m.name);
    if (IsPrimitive(m.type)) v = HashString(v, m.type);
    v = HashUpdate(v, static_cast<char>(m.dimensions.size()));
    for (const auto& d : m.dimensions) {
      v = HashUpdate(v, static_cast<char>(d.variable ? 1 : 0));
      v = HashString(v, d.size);
    }
  }
  return v;
}

// ---- the bounds check --------------------------------------------------------------------------

class Walker {
 public:
  Walker(const LcmSchema& schema, const uint8_t* data, size_t size, const LcmLimits& limits)
      : schema_(schema), p_(data), size_(size), limits_(limits) {}

  std::string Run(const LcmStruct& s, int64_t fingerprint) {
    if (size_ < 8) return s.name + ": " + std::to_string(size_) + " bytes, the fingerprint needs 8";
    const auto hash = static_cast<int64_t>(ReadBig(8));
    if (hash != fingerprint)
      return s.name + ": fingerprint " + Hex(hash) + " is not " + s.name + "'s (" +
             Hex(fingerprint) + "): another type or another version of it";
    std::string why = WalkStruct(s, 0);
    if (why.empty() && pos_ != size_)
      why = s.name + ": " + std::to_string(size_ - pos_) + " bytes after the end of the message";
    return why;
  }

 private:
  static constexpr int kMaxDepth = 32;  // nested structs (a self-containing type: data-driven)

  size_t Left() const { return size_ - pos_; }
  uint64_t ReadBig(int n) {
    uint64_t v = 0;
    for (int k = 0; k < n; ++k) v = (v << 8) | p_[pos_ + static_cast<size_t>(k)];
    pos_ += static_cast<size_t>(n);
    return v;
  }
  static int64_t SignExtend(uint64_t v, int bytes) {
    if (bytes == 8) return static_cast<int64_t>(v);
    const uint64_t sign = uint64_t{1} << (8 * bytes - 1);
    return static_cast<int64_t>((v ^ sign)) - static_cast<int64_t>(sign);
  }
  static std::string Hex(int64_t v) {
    static const char* digits = "0123456789abcdef";
    std::string s = "0x";
    for (int k = 15; k >= 0; --k) s += digits[(static_cast<uint64_t>(v) >> (4 * k)) & 0xF];
    return s;
  }
  std::string Field(const LcmStruct& s, const LcmMember& m) const { return s.name + "." + m.name; }

  std::string WalkStruct(const LcmStruct& s, int depth) {
    if (depth > kMaxDepth) return s.name + ": nested deeper than " + std::to_string(kMaxDepth);
    std::vector<int64_t> ints(s.members.size(), 0);  // scalar integer members, for dimensions
    for (size_t i = 0; i < s.members.size(); ++i) {
      const LcmMember& m = s.members[i];
      // Element count: the product of the dimensions, each checked before it is used.
      int64_t count = 1, last_n = 0;
      for (const auto& d : m.dimensions) {
        int64_t n = d.constant;
        if (d.variable) {
          size_t k = 0;
          while (s.members[k].name != d.size) ++k;  // the parser checked that it exists
          n = ints[k];
          const std::string len = s.name + "." + d.size + " = " + std::to_string(n);
          if (n < 0) return len + " is negative (" + m.name + "[" + d.size + "])";
          // Every element takes at least one encoded byte: a length beyond the bytes left is a
          // lie whatever the element type (checked before multiplying, so nothing overflows).
          if (static_cast<uint64_t>(n) > Left())
            return len + " exceeds the " + std::to_string(Left()) + " bytes left (" + m.name + "[" +
                   d.size + "])";
          if (n > limits_.max_array_length)
            return len + " exceeds the limit of " + std::to_string(limits_.max_array_length) +
                   " (" + m.name + "[" + d.size + "])";
        }
        last_n = n;
        if (__builtin_mul_overflow(count, n, &count) ||
            count > limits_.max_array_length * limits_.max_array_length)
          return Field(s, m) + ": more elements than the limit";
      }
      const auto prim = Primitives().find(m.type);
      if (prim != Primitives().end() && prim->second > 0) {
        const int width = prim->second;
        if (static_cast<uint64_t>(count) > Left() / static_cast<uint64_t>(width)) {
          if (!m.dimensions.empty() && m.dimensions.back().variable)
            return s.name + "." + m.dimensions.back().size + " = " + std::to_string(last_n) + ": " +
                   m.name + " needs " + std::to_string(count * width) + " bytes, " +
                   std::to_string(Left()) + " left";
          return Field(s, m) + ": needs " + std::to_string(count * width) + " bytes, " +
                 std::to_string(Left()) + " left (message truncated)";
        }
        if (m.dimensions.empty() && IsInteger(m.type)) {
          ints[i] = SignExtend(ReadBig(width), width);
        } else {
          pos_ += static_cast<size_t>(count * width);
        }
      } else if (prim != Primitives().end()) {  // string
        for (int64_t e = 0; e < count; ++e)
          if (std::string why = WalkString(s, m); !why.empty()) return why;
      } else {
        const LcmStruct* nested = schema_.Find(m.type);
        if (nested == nullptr) return Field(s, m) + ": no schema for type " + m.type;
        for (int64_t e = 0; e < count; ++e)
          if (std::string why = WalkStruct(*nested, depth + 1); !why.empty())
            return Field(s, m) + ": " + why;
      }
    }
    return {};
  }

  std::string WalkString(const LcmStruct& s, const LcmMember& m) {
    if (Left() < 4)
      return Field(s, m) + ": the string length needs 4 bytes, " + std::to_string(Left()) +
             " left (message truncated)";
    const int64_t n = SignExtend(ReadBig(4), 4);
    const std::string len = Field(s, m) + ": string length " + std::to_string(n);
    // The length counts the terminating NUL: 0 would make the decoder assign n − 1 = −1 bytes.
    if (n < 1) return len + " is below 1 (it counts the terminating NUL)";
    if (n > limits_.max_string_bytes)
      return len + " exceeds the limit of " + std::to_string(limits_.max_string_bytes);
    if (static_cast<uint64_t>(n) > Left())
      return len + " exceeds the " + std::to_string(Left()) + " bytes left";
    pos_ += static_cast<size_t>(n);
    if (p_[pos_ - 1] != 0) return len + ": no terminating NUL";
    return {};
  }

  const LcmSchema& schema_;
  const uint8_t* p_;
  size_t size_;
  size_t pos_ = 0;
  LcmLimits limits_;
};

}  // namespace

void LcmSchema::AddFile(std::string_view text, const std::string& source) {
  std::vector<LcmStruct> parsed = Parser(Tokenize(text, source), source).File();
  for (auto& s : parsed) {
    for (const auto& m : s.members)
      if (!IsPrimitive(m.type) && m.type == s.name && m.dimensions.empty())
        throw std::runtime_error(source + ": " + s.name + "." + m.name +
                                 " contains its own type without an array");
    if (Find(s.name) != nullptr)
      throw std::runtime_error(source + ": struct " + s.name + " defined twice");
    structs_.push_back(std::move(s));
  }
}

const LcmStruct* LcmSchema::Find(std::string_view name) const {
  if (const size_t dot = name.rfind('.'); dot != std::string_view::npos)
    name = name.substr(dot + 1);
  for (const auto& s : structs_)
    if (s.name == name) return &s;
  return nullptr;
}

uint64_t LcmSchema::HashOf(const LcmStruct& s, std::vector<const LcmStruct*>& parents) const {
  // The generated _computeHash: 0 for a type already on the path (recursive types), else the
  // struct's hash plus each non-primitive member's, rotated left by one.
  if (std::find(parents.begin(), parents.end(), &s) != parents.end()) return 0;
  parents.push_back(&s);
  auto hash = static_cast<uint64_t>(StructHash(s));
  for (const auto& m : s.members) {
    if (IsPrimitive(m.type)) continue;
    const LcmStruct* nested = Find(m.type);
    if (nested == nullptr)
      throw std::runtime_error(s.source + ": " + s.name + "." + m.name + ": unknown type " +
                               m.type);
    hash += HashOf(*nested, parents);
  }
  parents.pop_back();
  return (hash << 1) + ((hash >> 63) & 1);
}

int64_t LcmSchema::Fingerprint(const LcmStruct& s) const {
  std::vector<const LcmStruct*> parents;
  return static_cast<int64_t>(HashOf(s, parents));
}

std::string LcmSchema::Check(const LcmStruct& s, const void* data, size_t size,
                             const LcmLimits& limits) const {
  if (data == nullptr && size > 0) return s.name + ": no data";
  int64_t fingerprint = 0;
  try {
    fingerprint = Fingerprint(s);
  } catch (const std::exception& e) {
    return e.what();
  }
  return Walker(*this, static_cast<const uint8_t*>(data), size, limits).Run(s, fingerprint);
}

const LcmSchema& RcalLcmSchema() {
  static const LcmSchema schema = [] {
    LcmSchema s;
    for (const auto& f : detail::EmbeddedLcmFiles()) s.AddFile(f.text, f.name);
    return s;
  }();
  return schema;
}

std::string CheckLcmMessage(std::string_view type_name, int64_t fingerprint, const void* data,
                            size_t size, const LcmLimits& limits) {
  const LcmSchema& schema = RcalLcmSchema();
  const LcmStruct* s = schema.Find(type_name);
  if (s == nullptr) return std::string(type_name) + ": no schema in lcmtypes/ to check it against";
  if (schema.Fingerprint(*s) != fingerprint)
    return std::string(type_name) + ": the schema of " + s->source +
           " is not the one its code was generated from (fingerprints differ)";
  return schema.Check(*s, data, size, limits);
}

}  // namespace rcal::transport
