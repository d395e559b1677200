// RTDE framing and payloads (rtde.hpp): big-endian fields written and read byte by byte, so the
// layout does not depend on the host's byte order.
#include "robocal/robotio/rtde.hpp"

#include <fmt/core.h>

#include <bit>
#include <cstring>

namespace robocal::robotio::rtde {
namespace {

void put_be(std::string& out, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) out.push_back(static_cast<char>((v >> (8 * i)) & 0xffu));
}

std::uint64_t get_be(std::string_view in, std::size_t& offset, int bytes, const char* what) {
  if (offset + static_cast<std::size_t>(bytes) > in.size())
    throw RtdeFormatError(fmt::format("{}: the package ends after {} bytes, {} more needed", what,
                                      in.size(),
                                      offset + static_cast<std::size_t>(bytes) - in.size()));
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | static_cast<std::uint8_t>(in[offset++]);
  return v;
}

void require_type(const Package& package, PackageType type) {
  if (package.type != static_cast<std::uint8_t>(type))
    throw RtdeFormatError(fmt::format("expected a {} package ('{}'), got type {}", to_string(type),
                                      static_cast<char>(type), package.type));
}

std::vector<std::string> split_commas(std::string_view text) {
  std::vector<std::string> out;
  std::size_t start = 0;
  for (;;) {
    const std::size_t comma = text.find(',', start);
    out.emplace_back(
        text.substr(start, comma == std::string_view::npos ? text.npos : comma - start));
    if (comma == std::string_view::npos) return out;
    start = comma + 1;
  }
}

std::string join_commas(const std::vector<std::string>& items) {
  std::string out;
  for (const std::string& s : items) out += (out.empty() ? "" : ",") + s;
  return out;
}

// One number of a field, read as the type's wire format.
double get_number(std::string_view in, std::size_t& offset, const std::string& type) {
  const char* what = type.c_str();
  if (type == "DOUBLE" || type == "VECTOR3D" || type == "VECTOR6D")
    return std::bit_cast<double>(get_be(in, offset, 8, what));
  if (type == "INT32" || type == "VECTOR6INT32")
    return static_cast<std::int32_t>(static_cast<std::uint32_t>(get_be(in, offset, 4, what)));
  if (type == "UINT32" || type == "VECTOR6UINT32")
    return static_cast<double>(get_be(in, offset, 4, what));
  if (type == "UINT64") return static_cast<double>(get_be(in, offset, 8, what));
  return static_cast<double>(get_be(in, offset, 1, what));  // UINT8, BOOL
}

void put_number(std::string& out, double v, const std::string& type) {
  if (type == "DOUBLE" || type == "VECTOR3D" || type == "VECTOR6D") {
    put_f64(out, v);
  } else if (type == "INT32" || type == "VECTOR6INT32") {
    put_i32(out, static_cast<std::int32_t>(v));
  } else if (type == "UINT32" || type == "VECTOR6UINT32") {
    put_u32(out, static_cast<std::uint32_t>(v));
  } else if (type == "UINT64") {
    put_be(out, static_cast<std::uint64_t>(v), 8);
  } else {
    put_u8(out, static_cast<std::uint8_t>(v));
  }
}

}  // namespace

const char* to_string(PackageType type) {
  switch (type) {
    case PackageType::kRequestProtocolVersion:
      return "RTDE_REQUEST_PROTOCOL_VERSION";
    case PackageType::kGetUrControlVersion:
      return "RTDE_GET_URCONTROL_VERSION";
    case PackageType::kTextMessage:
      return "RTDE_TEXT_MESSAGE";
    case PackageType::kDataPackage:
      return "RTDE_DATA_PACKAGE";
    case PackageType::kSetupOutputs:
      return "RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS";
    case PackageType::kSetupInputs:
      return "RTDE_CONTROL_PACKAGE_SETUP_INPUTS";
    case PackageType::kStart:
      return "RTDE_CONTROL_PACKAGE_START";
    case PackageType::kPause:
      return "RTDE_CONTROL_PACKAGE_PAUSE";
  }
  return "?";
}

void put_u8(std::string& out, std::uint8_t v) {
  put_be(out, v, 1);
}
void put_u16(std::string& out, std::uint16_t v) {
  put_be(out, v, 2);
}
void put_u32(std::string& out, std::uint32_t v) {
  put_be(out, v, 4);
}
void put_i32(std::string& out, std::int32_t v) {
  put_be(out, static_cast<std::uint32_t>(v), 4);
}
void put_f64(std::string& out, double v) {
  put_be(out, std::bit_cast<std::uint64_t>(v), 8);
}
std::uint8_t get_u8(std::string_view in, std::size_t& offset, const char* what) {
  return static_cast<std::uint8_t>(get_be(in, offset, 1, what));
}
std::uint16_t get_u16(std::string_view in, std::size_t& offset, const char* what) {
  return static_cast<std::uint16_t>(get_be(in, offset, 2, what));
}
std::uint32_t get_u32(std::string_view in, std::size_t& offset, const char* what) {
  return static_cast<std::uint32_t>(get_be(in, offset, 4, what));
}
double get_f64(std::string_view in, std::size_t& offset, const char* what) {
  return std::bit_cast<double>(get_be(in, offset, 8, what));
}

std::string encode_package(PackageType type, std::string_view payload) {
  if (payload.size() + kHeaderBytes > 0xffffu)
    throw RtdeFormatError(fmt::format("a {} payload of {} bytes does not fit a package",
                                      to_string(type), payload.size()));
  std::string out;
  put_u16(out, static_cast<std::uint16_t>(payload.size() + kHeaderBytes));
  put_u8(out, static_cast<std::uint8_t>(type));
  out.append(payload);
  return out;
}

std::optional<Package> take_package(std::string& stream) {
  if (stream.size() < static_cast<std::size_t>(kHeaderBytes)) return std::nullopt;
  std::size_t offset = 0;
  const std::uint16_t size = get_u16(stream, offset, "package size");
  if (size < kHeaderBytes)
    throw RtdeFormatError(fmt::format("package size {} is smaller than the 3-byte header", size));
  if (stream.size() < size) return std::nullopt;
  Package p;
  p.type = static_cast<std::uint8_t>(stream[2]);
  p.payload = stream.substr(kHeaderBytes, size - kHeaderBytes);
  stream.erase(0, size);
  return p;
}

std::string encode_request_protocol_version(std::uint16_t version) {
  std::string payload;
  put_u16(payload, version);
  return encode_package(PackageType::kRequestProtocolVersion, payload);
}

std::string encode_get_urcontrol_version() {
  return encode_package(PackageType::kGetUrControlVersion, "");
}

std::string encode_setup_outputs(double frequency, const std::vector<std::string>& names) {
  std::string payload;
  put_f64(payload, frequency);
  payload += join_commas(names);
  return encode_package(PackageType::kSetupOutputs, payload);
}

std::string encode_start() {
  return encode_package(PackageType::kStart, "");
}

std::string encode_pause() {
  return encode_package(PackageType::kPause, "");
}

bool decode_accepted(const Package& package) {
  std::size_t offset = 0;
  return get_u8(package.payload, offset, "accepted") != 0;
}

std::string ControllerVersion::text() const {
  return fmt::format("{}.{}.{}.{}", major, minor, bugfix, build);
}

ControllerVersion decode_controller_version(const Package& package) {
  require_type(package, PackageType::kGetUrControlVersion);
  std::size_t offset = 0;
  ControllerVersion v;
  v.major = get_u32(package.payload, offset, "major");
  v.minor = get_u32(package.payload, offset, "minor");
  v.bugfix = get_u32(package.payload, offset, "bugfix");
  v.build = get_u32(package.payload, offset, "build");
  return v;
}

OutputRecipe decode_output_recipe(const Package& package) {
  require_type(package, PackageType::kSetupOutputs);
  std::size_t offset = 0;
  OutputRecipe r;
  r.id = get_u8(package.payload, offset, "output recipe id");
  r.types = split_commas(std::string_view(package.payload).substr(offset));
  return r;
}

std::vector<std::string> unknown_outputs(const std::vector<std::string>& names,
                                         const OutputRecipe& recipe) {
  if (names.size() != recipe.types.size())
    throw RtdeFormatError(fmt::format("asked for {} outputs, the controller typed {}", names.size(),
                                      recipe.types.size()));
  std::vector<std::string> unknown;
  for (std::size_t i = 0; i < names.size(); ++i)
    if (recipe.types[i] == "NOT_FOUND") unknown.push_back(names[i]);
  return unknown;
}

TextMessage decode_text_message(const Package& package) {
  require_type(package, PackageType::kTextMessage);
  const std::string_view in = package.payload;
  std::size_t offset = 0;
  TextMessage m;
  auto text = [&](const char* what) {
    const std::uint8_t n = get_u8(in, offset, what);
    if (offset + n > in.size())
      throw RtdeFormatError(
          fmt::format("{}: {} bytes announced, {} left", what, n, in.size() - offset));
    std::string s(in.substr(offset, n));
    offset += n;
    return s;
  };
  m.message = text("message");
  m.source = text("source");
  m.level = get_u8(in, offset, "warning level");
  return m;
}

int field_count(const std::string& type) {
  if (type == "VECTOR6D" || type == "VECTOR6INT32" || type == "VECTOR6UINT32") return 6;
  if (type == "VECTOR3D") return 3;
  if (type == "DOUBLE" || type == "INT32" || type == "UINT32" || type == "UINT64" ||
      type == "UINT8" || type == "BOOL")
    return 1;
  throw RtdeFormatError(fmt::format("unknown field type '{}'", type));
}

DataPackage decode_data_package(const Package& package, const std::vector<std::string>& types) {
  require_type(package, PackageType::kDataPackage);
  std::size_t offset = 0;
  DataPackage d;
  d.recipe_id = get_u8(package.payload, offset, "recipe id");
  for (const std::string& type : types) {
    FieldValues v(static_cast<std::size_t>(field_count(type)));
    for (double& x : v) x = get_number(package.payload, offset, type);
    d.fields.push_back(std::move(v));
  }
  if (offset != package.payload.size())
    throw RtdeFormatError(fmt::format("data package of {} bytes, its recipe takes {}",
                                      package.payload.size(), offset));
  return d;
}

std::string encode_data_package(std::uint8_t recipe_id, const std::vector<std::string>& types,
                                const std::vector<FieldValues>& fields) {
  std::string payload;
  put_u8(payload, recipe_id);
  for (std::size_t i = 0; i < types.size(); ++i) {
    const auto n = static_cast<std::size_t>(field_count(types[i]));
    if (i >= fields.size() || fields[i].size() != n)
      throw RtdeFormatError(fmt::format("field {} ({}) needs {} numbers", i + 1, types[i], n));
    for (double v : fields[i]) put_number(payload, v, types[i]);
  }
  return encode_package(PackageType::kDataPackage, payload);
}

OutputSetupRequest decode_setup_outputs(const Package& package) {
  require_type(package, PackageType::kSetupOutputs);
  std::size_t offset = 0;
  OutputSetupRequest r;
  r.frequency = get_f64(package.payload, offset, "output frequency");
  r.names = split_commas(std::string_view(package.payload).substr(offset));
  return r;
}

std::string encode_accepted(PackageType type, bool accepted) {
  std::string payload;
  put_u8(payload, accepted ? 1 : 0);
  return encode_package(type, payload);
}

std::string encode_controller_version(const ControllerVersion& version) {
  std::string payload;
  for (std::uint32_t v : {version.major, version.minor, version.bugfix, version.build})
    put_u32(payload, v);
  return encode_package(PackageType::kGetUrControlVersion, payload);
}

std::string encode_output_recipe(std::uint8_t id, const std::vector<std::string>& types) {
  std::string payload;
  put_u8(payload, id);
  payload += join_commas(types);
  return encode_package(PackageType::kSetupOutputs, payload);
}

std::string encode_text_message(const TextMessage& message) {
  std::string payload;
  // Each text carries a one-byte length: longer texts are cut at 255 bytes.
  for (const std::string* text : {&message.message, &message.source}) {
    const std::string cut = text->substr(0, 255);
    put_u8(payload, static_cast<std::uint8_t>(cut.size()));
    payload += cut;
  }
  put_u8(payload, static_cast<std::uint8_t>(message.level));
  return encode_package(PackageType::kTextMessage, payload);
}

}  // namespace robocal::robotio::rtde
