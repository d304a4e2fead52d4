#include "texstream/protocol/completion_check.hpp"

#include <optional>
#include <string>

namespace texstream {

namespace {
Error bad(const std::string& what) { return make_error(ErrorCode::kProtocol, "completion record: " + what); }
}  // namespace

Result<CheckedCompletion> check_completion(const CompletionRecord& r, uint32_t slot_count, uint64_t slot_bytes) {
  if (r.status == 0 || r.status > kMaxCompletionStatus) return bad("field 'status' = " + std::to_string(r.status));
  CheckedCompletion c{};
  c.status = static_cast<CompletionStatus>(r.status);
  if (r.request_kind == static_cast<uint32_t>(RequestKind::kLoad)) {
    if (r.page_x != 0 || r.page_y != 0) {
      return bad("fields 'page_x'/'page_y' = " + std::to_string(r.page_x) + "," + std::to_string(r.page_y) +
                 " on a mip's completion");
    }
  } else if (r.request_kind != static_cast<uint32_t>(RequestKind::kLoadPage)) {
    return bad("field 'request_kind' = " + std::to_string(r.request_kind));
  }
  c.kind = static_cast<RequestKind>(r.request_kind);
  c.texture = TextureId(r.texture_id);
  c.mip = MipLevel(r.mip_level);
  c.page_file = r.texture_id;
  c.page = pages::PageId{r.mip_level, r.page_x, r.page_y};
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
  if (c.kind != RequestKind::kLoad) return bad("a page's completion checked as a mip's");
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

Status check_against_page_file(const CheckedCompletion& c, const pages::PageFile& file) {
  if (c.kind != RequestKind::kLoadPage) return bad("a mip's completion checked as a page's");
  const pages::PageGeometry& g = file.geometry();
  const std::string page = "page file " + std::to_string(c.page_file) + " level " + std::to_string(c.page.level) +
                           " page " + std::to_string(c.page.x) + "," + std::to_string(c.page.y);
  const std::optional<pages::PageIndexEntry> entry = file.entry(c.page);  // nullopt outside the quadtree too
  if (!entry) return bad(page + " is not stored in the page file (or lies outside its quadtree)");
  if (c.format != g.format) {
    return bad(std::string("field 'format' = ") + std::string(to_string(c.format)) + " but " + page + " is " +
               std::string(to_string(g.format)));
  }
  if (c.extent != Extent2D{g.stored_side(), g.stored_side()}) {
    return bad("extent " + std::to_string(c.extent.width) + "x" + std::to_string(c.extent.height) + " but " + page +
               " is " + std::to_string(g.stored_side()) + " texels square with its borders");
  }
  if (c.byte_size != entry->bytes) {
    return bad("field 'byte_size' = " + std::to_string(c.byte_size) + " but " + page + " has " +
               std::to_string(entry->bytes));
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
