#pragma once
// Universal Robots' Real-Time Data Exchange (RTDE, TCP port 30004) as pure functions over bytes:
// the package framing and the payloads robocal sends and reads, in protocol version 2. Both the
// UR link and the simulated controller use these; the tests check them byte for byte against
// packages written out by hand from UR's RTDE guide.
//
// Framing (RTDE guide, "Header"): every package is uint16 size (the whole package, header
// included), uint8 type, then the payload. All numbers are big-endian (network order); doubles
// are IEEE 754 binary64.
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace robocal::robotio::rtde {

// Package types: the ASCII letter of each command.
enum class PackageType : std::uint8_t {
  kRequestProtocolVersion = 'V',  // 86
  kGetUrControlVersion = 'v',     // 118
  kTextMessage = 'M',             // 77
  kDataPackage = 'U',             // 85
  kSetupOutputs = 'O',            // 79
  kSetupInputs = 'I',             // 73
  kStart = 'S',                   // 83
  kPause = 'P',                   // 80
};
const char* to_string(PackageType type);

inline constexpr std::uint16_t kProtocolVersion = 2;
inline constexpr int kHeaderBytes = 3;

// A package that does not follow the guide (too short, an unknown field type, a size that
// disagrees with its payload). The link names the controller around it.
class RtdeFormatError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct Package {
  std::uint8_t type = 0;
  std::string payload;
};

// ---- framing ----------------------------------------------------------------------------------
std::string encode_package(PackageType type, std::string_view payload);
// Takes the first complete package off the front of `stream`; nullopt while it is incomplete.
// Throws RtdeFormatError when the size field is smaller than the header.
std::optional<Package> take_package(std::string& stream);

// ---- big-endian fields ------------------------------------------------------------------------
void put_u8(std::string& out, std::uint8_t v);
void put_u16(std::string& out, std::uint16_t v);
void put_u32(std::string& out, std::uint32_t v);
void put_i32(std::string& out, std::int32_t v);
void put_f64(std::string& out, double v);
// Readers of a payload from `offset` on; they advance `offset` and throw RtdeFormatError naming
// `what` when the payload ends first.
std::uint8_t get_u8(std::string_view in, std::size_t& offset, const char* what);
std::uint16_t get_u16(std::string_view in, std::size_t& offset, const char* what);
std::uint32_t get_u32(std::string_view in, std::size_t& offset, const char* what);
double get_f64(std::string_view in, std::size_t& offset, const char* what);

// ---- client requests (what robocal sends) -----------------------------------------------------
std::string encode_request_protocol_version(std::uint16_t version);
std::string encode_get_urcontrol_version();
// Protocol v2: double output_frequency (Hz), then the variable names joined by commas.
std::string encode_setup_outputs(double frequency, const std::vector<std::string>& names);
std::string encode_start();
std::string encode_pause();

// ---- controller replies -----------------------------------------------------------------------
// 'V', 'S', 'P': uint8 accepted (1) or not (0).
bool decode_accepted(const Package& package);
struct ControllerVersion {
  std::uint32_t major = 0, minor = 0, bugfix = 0, build = 0;
  std::string text() const;  // "5.11.0.108"
};
ControllerVersion decode_controller_version(const Package& package);
// 'O' reply: uint8 recipe id, then one type per requested name, comma-separated ("NOT_FOUND" for a
// name the controller does not know).
struct OutputRecipe {
  std::uint8_t id = 0;
  std::vector<std::string> types;
};
OutputRecipe decode_output_recipe(const Package& package);
// The names whose type came back NOT_FOUND (empty when the whole recipe is known). Throws
// RtdeFormatError when the counts of names and types differ.
std::vector<std::string> unknown_outputs(const std::vector<std::string>& names,
                                         const OutputRecipe& recipe);
// 'M' (protocol v2): uint8 message length, message, uint8 source length, source, uint8 level.
struct TextMessage {
  std::string message, source;
  int level = 0;  // 0 exception, 1 error, 2 warning, 3 info
};
TextMessage decode_text_message(const Package& package);

// ---- data packages ----------------------------------------------------------------------------
// Values of one field: 1 (DOUBLE, INT32, UINT32, UINT8, BOOL, UINT64), 3 (VECTOR3D) or 6 (VECTOR6D,
// VECTOR6INT32, VECTOR6UINT32) numbers.
using FieldValues = std::vector<double>;
// Numbers a field type carries; throws RtdeFormatError for a type this codec does not read.
int field_count(const std::string& type);
struct DataPackage {
  std::uint8_t recipe_id = 0;
  std::vector<FieldValues> fields;  // in recipe order
};
DataPackage decode_data_package(const Package& package, const std::vector<std::string>& types);
std::string encode_data_package(std::uint8_t recipe_id, const std::vector<std::string>& types,
                                const std::vector<FieldValues>& fields);

// ---- the controller side (the simulator reads requests and writes replies) --------------------
struct OutputSetupRequest {
  double frequency = 0.0;
  std::vector<std::string> names;
};
OutputSetupRequest decode_setup_outputs(const Package& package);
std::string encode_accepted(PackageType type, bool accepted);
std::string encode_controller_version(const ControllerVersion& version);
std::string encode_output_recipe(std::uint8_t id, const std::vector<std::string>& types);
std::string encode_text_message(const TextMessage& message);

}  // namespace robocal::robotio::rtde
