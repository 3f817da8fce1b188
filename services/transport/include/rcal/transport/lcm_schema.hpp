// The LCM message schemas (lcmtypes/*.lcm, parsed from their text embedded at build time) and a
// bounds check that walks encoded bytes by a schema before any generated decoder touches them.
//
// Why: LCM 1.3.1's generated C++ decoders resize a vector from a length field before checking it
// against the bytes present (num_joints = 2^28 + 6 in a 422-byte message resizes to 2 GB, then
// 8·n overflows int and the read runs past the buffer; num_joints = −1 throws length_error from
// resize). CheckLcmMessage refuses such bytes first, so that decoding a message allocates at most
// a small multiple of its own size: every array element, every string takes at least one encoded
// byte, and each is checked to fit in the bytes left.
//
// The wire format (LCM type specification): big-endian; an 8-byte fingerprint, then each member in
// declaration order; int8_t/byte/boolean 1 byte, int16_t 2, int32_t/float 4, int64_t/double 8; a
// string is an int32 length that counts its terminating NUL, then that many bytes; an array
// repeats its element per dimension (a dimension is a constant or an earlier integer member);
// nested structs are encoded without their own fingerprint.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

namespace rcal::transport {

/// One dimension of an array member: a constant size, or the value of an earlier integer member.
struct LcmDimension {
  bool variable = false;  ///< true: the size is the member `size`
  std::string size;       ///< as written in the .lcm file ("3", "num_joints")
  int64_t constant = 0;   ///< the size when !variable
};

/// One member of a struct. Constants (`const int32_t X = 1;`) are not members: not on the wire.
struct LcmMember {
  std::string type;  ///< "double", "string", ... or a struct name (package stripped)
  std::string name;
  std::vector<LcmDimension> dimensions;  ///< empty: a scalar
};

/// One `struct` of a .lcm file.
struct LcmStruct {
  std::string package;  ///< "rcal"
  std::string name;     ///< "pose_measurement_t" (LCM's getTypeName())
  std::vector<LcmMember> members;
  std::string source;  ///< the .lcm file it came from (for messages)
};

/// The most a message may claim, whatever the bytes present allow: far above any legitimate rcal
/// message (a 6-axis arm has 6 joints, the extended models under 100 parameters), far below what
/// would hurt a process.
struct LcmLimits {
  int64_t max_array_length = 4096;   ///< elements per dimension of a variable-length array
  int64_t max_string_bytes = 65536;  ///< bytes of one string, its NUL included
};

/// A set of parsed struct definitions.
class LcmSchema {
 public:
  /// Parses the text of a .lcm file and adds its structs. Throws std::runtime_error naming
  /// `source` and the line on a syntax error, an unknown primitive or a dimension that is not an
  /// earlier integer member.
  void AddFile(std::string_view text, const std::string& source);

  /// The struct of that name (with or without its package), or nullptr.
  const LcmStruct* Find(std::string_view name) const;
  const std::vector<LcmStruct>& structs() const { return structs_; }

  /// The fingerprint lcm-gen's code puts first on the wire (the generated getHash()): lcm-gen's
  /// hash of member names, primitive types and dimensions, plus the nested structs' own
  /// fingerprints, rotated left by one bit. Throws std::runtime_error for an unknown nested type.
  int64_t Fingerprint(const LcmStruct& s) const;

  /// Checks encoded bytes (fingerprint first) against `s`: the fingerprint equals
  /// Fingerprint(s), every length is >= 0, within `limits` and fits in the bytes left, every
  /// string holds at least its NUL and ends with it, and the message ends exactly at `size`.
  /// Returns "" when the bytes are safe to decode, else the reason naming the type and the field
  /// ("pose_measurement_t.num_joints = 268435462 exceeds the 414 bytes left").
  std::string Check(const LcmStruct& s, const void* data, size_t size,
                    const LcmLimits& limits = {}) const;

 private:
  uint64_t HashOf(const LcmStruct& s, std::vector<const LcmStruct*>& parents) const;
  std::vector<LcmStruct> structs_;
};

/// The schemas of rcal's own messages: every lcmtypes/*.lcm file, embedded at build time and
/// parsed once (thread-safe).
const LcmSchema& RcalLcmSchema();

/// RcalLcmSchema().Check for the type named `type_name` (Msg::getTypeName()), whose generated code
/// has the fingerprint `fingerprint` (Msg::getHash()). Returns "" when safe to decode, else the
/// reason. A type without a schema, or whose schema's fingerprint differs from `fingerprint` (the
/// embedded .lcm text is not what the code was generated from), is refused: it cannot be checked.
std::string CheckLcmMessage(std::string_view type_name, int64_t fingerprint, const void* data,
                            size_t size, const LcmLimits& limits = {});

/// Checks `data` with CheckLcmMessage, then decodes it into `msg`. Returns "" on success, else
/// the reason (the check's, or "does not decode as T" when the generated decoder fails or throws).
/// Every decode of LCM data in rcal goes through this (Transport::Subscribe, the log readers).
template <typename Msg>
std::string DecodeLcm(const void* data, size_t size, Msg* msg) {
  std::string refused = CheckLcmMessage(Msg::getTypeName(), Msg::getHash(), data, size);
  if (!refused.empty()) return refused;
  try {
    if (msg->decode(data, 0, static_cast<int>(size)) == static_cast<int>(size)) return {};
  } catch (...) {  // generated code does not throw, but allocation can
  }
  return std::to_string(size) + " bytes do not decode as " + Msg::getTypeName();
}

namespace detail {
/// The embedded .lcm files: (file name, text). Defined in the generated lcm_schema_text.cpp.
struct EmbeddedLcmFile {
  const char* name;
  const char* text;
};
const std::vector<EmbeddedLcmFile>& EmbeddedLcmFiles();
}  // namespace detail

}  // namespace rcal::transport
