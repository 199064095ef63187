#include "common/avatar/transfer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>

#include "common/core/check.h"
#include "common/light/spherical_harmonics.h"

namespace vistream {

TransferIntegrator::TransferIntegrator(int maskSide, const TransferOptions& options)
    : side_(maskSide), orders_(options.orders), terms_(shTerms(options.orders)) {
  VS_CHECK(options.orders >= 1 && options.orders <= kMaxShOrder + 1);
  VS_CHECK(maskSide >= 8 && maskSide % 8 == 0);
  const int block = options.downsample ? 4 : 1;
  size_t disk = 0;
  std::vector<float> y(static_cast<size_t>(terms_));
  for (int by = 0; by < maskSide; by += block)
    for (int bx = 0; bx < maskSide; bx += block) {
      std::vector<double> sum(size_t(terms_), 0.0);
      glm::vec3 direction(0.0f);
      std::vector<std::pair<uint32_t, uint64_t>> bits;
      int count = 0;
      for (int py = by; py < by + block; ++py)
        for (int px = bx; px < bx + block; ++px) {
          if (!maskPixelInDisk(maskSide, px, py)) continue;
          const glm::vec3 s = maskDirection(maskSide, px, py);
          shEvaluate(s, orders_, y.data());
          for (int k = 0; k < terms_; ++k) sum[size_t(k)] += y[size_t(k)];
          direction += s;
          ++count;
          const uint32_t p = uint32_t(py * maskSide + px);
          if (bits.empty() || bits.back().first != (p >> 6)) bits.emplace_back(p >> 6, 0);
          bits.back().second |= uint64_t(1) << (p & 63);
        }
      if (count == 0) continue;
      disk += size_t(count);
      samples_.push_back({uint32_t(wordIndex_.size()), uint32_t(bits.size()), float(count)});
      for (const auto& [word, mask] : bits) {
        wordIndex_.push_back(word);
        wordBits_.push_back(mask);
      }
      directions_.push_back(glm::normalize(direction));
      for (int k = 0; k < terms_; ++k) basis_.push_back(float(sum[size_t(k)]));  // count x mean
    }
  // Each pixel's share of the projected solid angle pi.
  const float area = std::numbers::pi_v<float> / float(disk);
  for (float& b : basis_) b *= area;
  if (block == 1) {
    pixelSample_.assign(size_t(maskSide) * size_t(maskSide), -1);
    diskBits_.assign((size_t(maskSide) * size_t(maskSide) + 63) / 64, 0);
    unblocked_.assign(size_t(terms_), 0.0f);
    std::vector<double> sum(size_t(terms_), 0.0);
    for (size_t k = 0; k < samples_.size(); ++k) {
      const uint32_t w = wordIndex_[samples_[k].firstWord];
      pixelSample_[size_t(w) * 64 + size_t(std::countr_zero(wordBits_[samples_[k].firstWord]))] =
          int32_t(k);
      diskBits_[w] |= wordBits_[samples_[k].firstWord];
      for (int i = 0; i < terms_; ++i) sum[size_t(i)] += basis_[k * size_t(terms_) + size_t(i)];
    }
    for (int i = 0; i < terms_; ++i) unblocked_[size_t(i)] = float(sum[size_t(i)]);
  }
}

template <class Lobe>
void TransferIntegrator::integrate(const VisibilityMask& mask, const TangentFrame& frame,
                                   Lobe&& lobe, float* out) const {
  VS_CHECK_EQ(mask.side(), side_);
  float local[25] = {};
  const uint64_t* bits = mask.data();
  for (size_t k = 0; k < samples_.size(); ++k) {
    const Sample& s = samples_[k];
    int blocked = 0;
    for (uint32_t w = s.firstWord; w < s.firstWord + s.words; ++w)
      blocked += std::popcount(bits[wordIndex_[w]] & wordBits_[w]);
    const float open = 1.0f - float(blocked) / s.pixels;
    if (open <= 0.0f) continue;
    const float f = open * lobe(directions_[k]);
    if (f == 0.0f) continue;
    const float* b = basis_.data() + k * size_t(terms_);
    for (int i = 0; i < terms_; ++i) local[i] += f * b[i];
  }
  const ShRotation toWorld(glm::mat3(frame.t, frame.b, frame.n), orders_);
  toWorld.apply(local, out);
}

void TransferIntegrator::diffuse(const VisibilityMask& mask, const TangentFrame& frame,
                                 float* out) const {
  if (!pixelSample_.empty()) {
    // Per pixel, visiting the fewer of the blocked and the open pixels: the
    // open sky minus what is blocked, or the open pixels' sum (exactly 0
    // when all are blocked).
    VS_CHECK_EQ(mask.side(), side_);
    const uint64_t* bits = mask.data();
    const int words = mask.words();
    size_t blocked = 0;
    for (int w = 0; w < words; ++w)
      blocked += size_t(std::popcount(bits[w] & diskBits_[size_t(w)]));
    const bool mostlyBlocked = 2 * blocked > samples_.size();
    float local[25];
    if (mostlyBlocked)
      std::fill_n(local, terms_, 0.0f);
    else
      std::copy_n(unblocked_.data(), terms_, local);
    const float sign = mostlyBlocked ? 1.0f : -1.0f;
    for (int w = 0; w < words; ++w) {
      const uint64_t visit = (mostlyBlocked ? ~bits[w] : bits[w]) & diskBits_[size_t(w)];
      for (uint64_t set = visit; set != 0; set &= set - 1) {
        const int32_t k = pixelSample_[size_t(w) * 64 + size_t(std::countr_zero(set))];
        const float* b = basis_.data() + size_t(k) * size_t(terms_);
        for (int i = 0; i < terms_; ++i) local[i] += sign * b[i];
      }
    }
    const ShRotation toWorld(glm::mat3(frame.t, frame.b, frame.n), orders_);
    toWorld.apply(local, out);
    return;
  }
  integrate(
      mask, frame, [](const glm::vec3&) { return 1.0f; }, out);
}

void TransferIntegrator::glossy(const VisibilityMask& mask, const TangentFrame& frame,
                                const glm::vec3& reflected, float exponent, float* out) const {
  const float norm = (exponent + 1.0f) / (2.0f * std::numbers::pi_v<float>);
  const glm::vec3 r = frame.toLocal(reflected);
  integrate(
      mask, frame,
      [&](const glm::vec3& s) { return norm * std::pow(std::max(0.0f, glm::dot(s, r)), exponent); },
      out);
}

}  // namespace vistream
