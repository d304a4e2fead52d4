#include "texstream/render/cache/mip_fades.hpp"

#include <algorithm>
#include <bit>

namespace texstream::render {

void MipFades::on_publish(uint32_t slot, gpu::TextureGpu& t, uint32_t before) {
  const uint32_t finest = t.placement.y;
  // Evicted, coarser, or no fading: what is resident shows at once.
  if (!started_ || fade_s_ <= 0 || finest == gpu::kNotResident || (before != gpu::kNotResident && finest > before)) {
    t.colour.y = gpu::kNotResident;
    t.colour.z = 0;
    return;
  }
  if (finest == before) return;  // a coarser level under the same finest one: any fade goes on
  // A level arriving mid-fade: past half way the level that was fading in becomes the one faded from; before
  // that the old one stays and the fade goes on. Either way no frame jumps by more than half a level's change.
  if (std::bit_cast<float>(t.colour.z) <= 0.5f) {
    t.colour.y = before;
    t.colour.z = std::bit_cast<uint32_t>(1.0f);
  }
  if (!listed_.contains(TextureId(slot))) {  // the map's keys are slots here
    listed_.insert(TextureId(slot), 0);
    fading_.push_back(slot);
  }
}

void MipFades::advance(double dt_s, std::span<gpu::TextureGpu> table) {
  started_ = true;
  if (fade_s_ <= 0) return;
  const auto step = static_cast<float>(std::max(0.0, dt_s) / fade_s_);
  size_t kept = 0;
  for (const uint32_t id : fading_) {
    gpu::TextureGpu& t = table[id];
    const float left = std::max(0.0f, std::bit_cast<float>(t.colour.z) - step);
    t.colour.z = std::bit_cast<uint32_t>(left);
    if (left > 0.0f) {
      fading_[kept++] = id;
    } else {
      t.colour.y = gpu::kNotResident;
      listed_.erase(TextureId(id));
    }
  }
  fading_.resize(kept);
}

}  // namespace texstream::render
