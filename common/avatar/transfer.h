// Radiance transfer from a visibility mask (Kautz, Lehtinen and Aila 2004,
// Equation 3 and section 3.2): the projection onto the spherical harmonics
// of V(s) f_r max(0, n . s) over the hemisphere of a vertex, so that its
// exitant radiance is the dot product of the transfer vector with the
// environment's radiance coefficients (Equation 2).
//
// The mask's pixels sample the hemisphere by cosine importance (the disk is
// its projection, hemisphere_raster.h), so the integral is a sum over disk
// pixels of Y_i(s) (1 - blocked) times pi / (disk pixels): the cosine is in
// the sampling. Downsampling (the paper's optimisation) merges 4 x 4 pixel
// blocks into one sample with a grey occlusion (the share of its disk pixels
// blocked): 16 times fewer samples. The sum is taken in the tangent frame,
// where every sample's basis values (for a block, their mean over its
// pixels) are precomputed, and turned into the world frame once per vertex
// by an SH rotation (spherical_harmonics.h), so the coefficients pair with
// the environment's.
//
// BRDFs: diffuse (albedo / pi; the transfer holds the cosine and visibility,
// the albedo multiplies the result) and glossy (a normalized Phong lobe of
// exponent e about the view direction's reflection, times the cosine).
//
// Without downsampling every disk pixel is a sample, and diffuse transfer
// is the open hemisphere's (precomputed) minus the blocked pixels' basis
// values, visited by their set bits (or the open pixels' sum, when fewer are
// open): the work follows the smaller of the two sets, so
// full resolution costs little more than the downsampled sum and halves its
// error (the benchmark's knob table).
//
// Thread safety: immutable after construction; transfer() writes only `out`.
#pragma once

#include <glm/glm.hpp>
#include <vector>

#include "common/avatar/hemisphere_raster.h"
#include "common/core/tangent_frame.h"

namespace vistream {

struct TransferOptions {
  int orders = 5;  // SH orders 1..5: 1, 4, 9, 16 or 25 terms
  // 4 x 4 blocks of the mask, as in the paper. Off by default: measured on
  // the Fox, full resolution halves the error (1.6% against 3.0%) for about
  // 10% more time, since rasterization, not integration, is the cost here.
  bool downsample = false;
};

class TransferIntegrator {
 public:
  TransferIntegrator(int maskSide, const TransferOptions& options = {});

  int terms() const { return terms_; }
  int samples() const { return int(samples_.size()); }
  // Diffuse transfer (cosine times visibility) of a vertex with tangent
  // frame `frame` whose blockers are the set bits of `mask`, to out[0 ..
  // terms()).
  void diffuse(const VisibilityMask& mask, const TangentFrame& frame, float* out) const;
  // Glossy transfer: the cosine times visibility times a normalized Phong
  // lobe (e + 1) / (2 pi) (r . s)^e about `reflected` (unit, world).
  void glossy(const VisibilityMask& mask, const TangentFrame& frame, const glm::vec3& reflected,
              float exponent, float* out) const;

 private:
  struct Sample {
    uint32_t firstWord, words;  // its (word, bits) pairs in wordIndex_/wordBits_
    float pixels;               // disk pixels it stands for
  };
  template <class Lobe>
  void integrate(const VisibilityMask& mask, const TangentFrame& frame, Lobe&& lobe,
                 float* out) const;

  int side_, orders_, terms_;
  std::vector<Sample> samples_;
  std::vector<glm::vec3> directions_;  // per sample: mean local direction (unit)
  std::vector<float> basis_;           // per sample: terms_ weighted local basis values
  std::vector<uint32_t> wordIndex_;    // mask words a sample's pixels lie in
  std::vector<uint64_t> wordBits_;     // and its pixels' bits in each
  // Without downsampling: each mask pixel's sample (-1 outside the disk) and
  // the sum of every sample's basis values (the unblocked transfer).
  std::vector<int32_t> pixelSample_;
  std::vector<uint64_t> diskBits_;  // the pixels that are samples
  std::vector<float> unblocked_;
};

}  // namespace vistream
