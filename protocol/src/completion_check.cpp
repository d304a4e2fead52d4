#include "texstream/protocol/completion_check.hpp"

#include <string>

namespace texstream {

namespace {
Error bad(const std::string& what) { return make_error(ErrorCode::kProtocol, "completion record: " + what); }
}  // namespace

Result<CheckedCompletion> check_completion(const CompletionRecord& r, uint32_t slot_count, uint64_t slot_bytes) {
  if (r.status == 0 || r.status > kMaxCompletionStatus) return bad("field 'status' = " + std::to_string(r.status));
  CheckedCompletion c{};
  c.status = static_cast<CompletionStatus>(r.status);
  c.texture = TextureId(r.texture_id);
  c.mip = MipLevel(r.mip_level);
  c.generation = Generation(r.generation);
  c.checksum = r.checksum;
  if (c.status != CompletionStatus::kOk) {
    if (r.slot != kNoSlot) return bad("field 'slot' = " + std::to_string(r.slot) + " on a non-ok completion");
    c.slot = SlotIndex(kNoSlot);
    return c;
  }
  if (r.slot >= slot_count) {
    return bad("field 'slot' = " + std::to_string(r.slot) + " >= slot count " + std::to_string(slot_count));
  }
  if (r.byte_size == 0 || r.byte_size > slot_bytes) {
    return bad("field 'byte_size' = " + std::to_string(r.byte_size) + " outside (0, " + std::to_string(slot_bytes) +
               "]");
  }
  const auto format = texel_format_from_raw(r.format);
  if (!format) return bad("field 'format' = " + std::to_string(r.format));
  if (!valid_texture_extent(r.width, r.height)) {
    return bad("fields 'width'/'height' = " + std::to_string(r.width) + "x" + std::to_string(r.height));
  }
  c.slot = SlotIndex(r.slot);
  c.byte_size = r.byte_size;
  c.format = *format;
  c.extent = {r.width, r.height};
  return c;
}

Status check_against_texture(const CheckedCompletion& c, const TextureShape& shape) {
  if (c.mip.value >= shape.mip_count) {
    return bad("field 'mip_level' = " + std::to_string(c.mip.value) + " but texture " +
               std::to_string(c.texture.value) + " has " + std::to_string(shape.mip_count) + " mips");
  }
  if (c.format != shape.format) {
    return bad(std::string("field 'format' = ") + std::string(to_string(c.format)) + " but texture is " +
               std::string(to_string(shape.format)));
  }
  const Extent2D expected = mip_extent(shape.width, shape.height, c.mip.value);
  if (c.extent != expected) {
    return bad("extent " + std::to_string(c.extent.width) + "x" + std::to_string(c.extent.height) + " but mip " +
               std::to_string(c.mip.value) + " is " + std::to_string(expected.width) + "x" +
               std::to_string(expected.height));
  }
  const uint64_t bytes = mip_bytes(shape.format, expected);
  if (c.byte_size != bytes) {
    return bad("field 'byte_size' = " + std::to_string(c.byte_size) + " but the mip has " + std::to_string(bytes));
  }
  return ok_status();
}

const char* to_string(CompletionStatus status) {
  switch (status) {
    case CompletionStatus::kOk:
      return "ok";
    case CompletionStatus::kNotFound:
      return "not found";
    case CompletionStatus::kCorrupt:
      return "corrupt";
    case CompletionStatus::kTimedOut:
      return "timed out";
    case CompletionStatus::kCancelled:
      return "cancelled";
    case CompletionStatus::kIoError:
      return "i/o error";
    case CompletionStatus::kUnfilled:
      return "unfilled";
  }
  return "unknown";
}

}  // namespace texstream
