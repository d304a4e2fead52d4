#include "texstream/render/frame/frame_capture.hpp"

#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <stb_image_write.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <system_error>
#include <vector>

namespace texstream::render {

Result<FrameCapture> FrameCapture::create(const VulkanContext& ctx, uint32_t width, uint32_t height) {
  FrameCapture c;
  c.width_ = width;
  c.height_ = height;
  auto b =
      GpuBuffer::create(ctx, VkDeviceSize{width} * height * 4, VK_BUFFER_USAGE_TRANSFER_DST_BIT, MemoryUse::kHostRead);
  if (!b) return b.error();
  c.buffer_ = std::move(*b);
  return c;
}

void FrameCapture::record(VkCommandBuffer cmd, VkImage image) const {
  VkBufferImageCopy r{};
  r.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  r.imageExtent = {width_, height_, 1};
  vkCmdCopyImageToBuffer(cmd, image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, buffer_.handle(), 1, &r);
  VkMemoryBarrier b{};
  b.sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER;
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &b, 0, nullptr, 0,
                       nullptr);
}

Status FrameCapture::write_png(const std::filesystem::path& file) const {
  std::error_code ec;
  std::filesystem::create_directories(file.parent_path(), ec);
  if (ec) return make_error(ErrorCode::kIo, file.parent_path().string() + ": cannot create: " + ec.message());
  // Encoded in memory, then written and checked here: stbi_write_png() ignores fwrite's result, so on a full
  // disk it left empty or truncated PNGs and reported success (19 of 30 frames of a run on a 1 MiB tmpfs).
  std::vector<unsigned char> png;
  const int encoded = stbi_write_png_to_func(
      [](void* context, void* data, int size) {
        auto* out = static_cast<std::vector<unsigned char>*>(context);
        out->insert(out->end(), static_cast<unsigned char*>(data), static_cast<unsigned char*>(data) + size);
      },
      &png, static_cast<int>(width_), static_cast<int>(height_), 4, buffer_.bytes().data(),
      static_cast<int>(width_ * 4));
  if (!encoded) return make_error(ErrorCode::kIo, file.string() + ": PNG encoding failed");
  std::ofstream out(file, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
  out.close();
  if (!out) {
    const std::string why = errno != 0 ? std::strerror(errno) : "write failed";
    std::filesystem::remove(file, ec);  // no half a picture left behind under the frame's name
    return make_error(ErrorCode::kIo, file.string() + ": cannot write the frame (" + why + ")");
  }
  return ok_status();
}

}  // namespace texstream::render
