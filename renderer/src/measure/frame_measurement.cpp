#include "texstream/render/measure/frame_measurement.hpp"

#include <string>
#include <utility>

#include "texstream/render/measure/image_metrics.hpp"

namespace texstream::render {

Result<std::unique_ptr<FrameMeasurement>> FrameMeasurement::open(const std::filesystem::path& reference_dir,
                                                                 const std::filesystem::path& output_dir,
                                                                 uint32_t width, uint32_t height) {
  auto reference = ReferenceFrames::open(reference_dir, width, height);
  if (!reference) return reference.error();
  auto spill = FrameSpill::create(output_dir / "frames.spill", size_t{width} * height * 4);
  if (!spill) return spill.error();
  return std::unique_ptr<FrameMeasurement>(
      new FrameMeasurement(std::move(*reference), std::move(*spill), width, height));
}

Status FrameMeasurement::add(std::span<const std::byte> pixels) { return spill_.append(pixels); }

Status FrameMeasurement::measure(std::vector<FrameRecord>& frames) {
  if (frames.size() != spill_.frames()) {
    return make_error(ErrorCode::kInvalidArgument, std::to_string(frames.size()) + " frame records for " +
                                                       std::to_string(spill_.frames()) + " captured frames");
  }
  std::vector<std::byte> cur, prev;
  for (size_t i = 0; i < frames.size(); ++i) {
    FrameRecord& f = frames[i];
    TS_TRY(spill_.read(i, cur));
    const RgbaView frame{cur, width_, height_};
    auto ref = reference_.frame(f.index);
    if (!ref) return ref.error();
    auto err = compare_images(frame, *ref);
    if (!err) return err.error();
    f.mse = err->mse;
    f.psnr_db = err->psnr_db;
    f.ssim = err->ssim;
    if (f.camera_still && i > 0) f.popin_mse = mse_rgb(frame, RgbaView{prev, width_, height_});
    std::swap(prev, cur);
  }
  return ok_status();
}

}  // namespace texstream::render
