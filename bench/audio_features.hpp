// Audio descriptors for the benchmarks: MFCC frames of any audio (mfcc()), by default 13 cepstral
// coefficients, their deltas and delta-deltas (39 values a frame). audio_files.hpp reads the
// recordings they are computed from.
#pragma once

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstddef>
#include <vector>

namespace kdspace_bench {

namespace audio_detail {

constexpr double pi = 3.14159265358979323846;
constexpr std::size_t mel_bands = 26;

// In-place radix-2 FFT of a power-of-two length.
inline void fft(std::vector<std::complex<double>>& x) {
  const std::size_t n = x.size();
  for (std::size_t i = 1, j = 0; i < n; ++i) {
    std::size_t bit = n >> 1;
    for (; j & bit; bit >>= 1) j ^= bit;
    j ^= bit;
    if (i < j) std::swap(x[i], x[j]);
  }
  for (std::size_t len = 2; len <= n; len <<= 1) {
    const std::complex<double> step = std::polar(1.0, -2 * pi / static_cast<double>(len));
    for (std::size_t start = 0; start < n; start += len) {
      std::complex<double> w = 1;
      for (std::size_t i = 0; i < len / 2; ++i, w *= step) {
        const std::complex<double> a = x[start + i], b = x[start + i + len / 2] * w;
        x[start + i] = a + b;
        x[start + i + len / 2] = a - b;
      }
    }
  }
}

inline double hz_to_mel(double hz) { return 2595 * std::log10(1 + hz / 700); }
inline double mel_to_hz(double mel) { return 700 * (std::pow(10, mel / 2595) - 1); }

}  // namespace audio_detail

/// What mfcc() computes a frame: `cepstra` coefficients (0 .. cepstra - 1), and with `deltas` their
/// regression deltas and delta-deltas (3 * cepstra values a frame).
struct MfccShape {
  std::size_t cepstra = 13;
  bool deltas = true;
  std::size_t dim() const { return deltas ? 3 * cepstra : cepstra; }
};

/// MFCC frames of `audio` (mono, at `rate` samples a second), row-major, shape.dim() floats each:
/// 25 ms Hamming-windowed frames every 10 ms, the power spectrum (FFT of the next power of two at
/// least a frame long), 26 triangular mel filters from 0 Hz to min(rate / 2, 8 kHz), log energies,
/// DCT-II. Every frame whose window and delta-deltas fit inside the audio: 4 frames are lost at each
/// end to the deltas.
inline std::vector<float> mfcc(const std::vector<double>& audio, double rate, const MfccShape& shape) {
  using namespace audio_detail;
  const std::size_t frame_length = static_cast<std::size_t>(0.025 * rate), step = static_cast<std::size_t>(0.010 * rate);
  std::size_t fft_length = 1;
  while (fft_length < frame_length) fft_length *= 2;
  if (audio.size() < frame_length) return {};
  const std::size_t total = (audio.size() - frame_length) / step + 1;
  const std::size_t pad = shape.deltas ? 4 : 0;  // frames each side that lack full delta-deltas
  if (total <= 2 * pad) return {};
  const std::size_t cepstra = shape.cepstra;

  // Mel filterbank on the FFT bins.
  const double top = std::min(rate / 2, 8000.0);
  const std::size_t bins = fft_length / 2 + 1;
  std::vector<double> edges(mel_bands + 2);
  for (std::size_t i = 0; i < edges.size(); ++i)
    edges[i] = mel_to_hz(hz_to_mel(top) * static_cast<double>(i) / static_cast<double>(mel_bands + 1));
  std::vector<double> filters(mel_bands * bins, 0.0);
  std::vector<std::size_t> first_bin(mel_bands, bins), last_bin(mel_bands, 0);  // each filter's nonzero bins
  for (std::size_t b = 0; b < mel_bands; ++b)
    for (std::size_t j = 0; j < bins; ++j) {
      const double hz = static_cast<double>(j) * rate / static_cast<double>(fft_length);
      const double rise = (hz - edges[b]) / (edges[b + 1] - edges[b]);
      const double fall = (edges[b + 2] - hz) / (edges[b + 2] - edges[b + 1]);
      filters[b * bins + j] = std::max(0.0, std::min(rise, fall));
      if (filters[b * bins + j] > 0) first_bin[b] = std::min(first_bin[b], j), last_bin[b] = j + 1;
    }

  std::vector<double> cepstrum(total * cepstra);
  std::vector<std::complex<double>> spectrum(fft_length);
  std::vector<double> log_energy(mel_bands);
  for (std::size_t f = 0; f < total; ++f) {
    std::fill(spectrum.begin(), spectrum.end(), 0.0);
    for (std::size_t s = 0; s < frame_length; ++s) {
      const double window = 0.54 - 0.46 * std::cos(2 * pi * static_cast<double>(s) / static_cast<double>(frame_length - 1));
      spectrum[s] = window * audio[f * step + s];
    }
    fft(spectrum);
    for (std::size_t b = 0; b < mel_bands; ++b) {
      double e = 0;
      for (std::size_t j = first_bin[b]; j < last_bin[b]; ++j) e += filters[b * bins + j] * std::norm(spectrum[j]);
      log_energy[b] = std::log(e + 1e-10);
    }
    for (std::size_t c = 0; c < cepstra; ++c) {
      double sum = 0;
      for (std::size_t b = 0; b < mel_bands; ++b)
        sum += log_energy[b] * std::cos(pi * static_cast<double>(c) * (static_cast<double>(b) + 0.5) / mel_bands);
      cepstrum[f * cepstra + c] = sum;
    }
  }

  // Regression deltas over +-2 frames: d_t = sum_{i=1,2} i (c_{t+i} - c_{t-i}) / 10.
  auto deltas = [&](const std::vector<double>& in) {
    std::vector<double> out(in.size(), 0.0);
    for (std::size_t f = 2; f + 2 < total; ++f)
      for (std::size_t c = 0; c < cepstra; ++c)
        out[f * cepstra + c] = ((in[(f + 1) * cepstra + c] - in[(f - 1) * cepstra + c]) +
                                2 * (in[(f + 2) * cepstra + c] - in[(f - 2) * cepstra + c])) / 10;
    return out;
  };
  const std::size_t frames = total - 2 * pad, dim = shape.dim();
  std::vector<float> out(frames * dim);
  const std::vector<double> delta = shape.deltas ? deltas(cepstrum) : std::vector<double>{};
  const std::vector<double> delta2 = shape.deltas ? deltas(delta) : std::vector<double>{};
  for (std::size_t f = 0; f < frames; ++f)
    for (std::size_t c = 0; c < cepstra; ++c) {
      out[f * dim + c] = static_cast<float>(cepstrum[(f + pad) * cepstra + c]);
      if (!shape.deltas) continue;
      out[f * dim + cepstra + c] = static_cast<float>(delta[(f + pad) * cepstra + c]);
      out[f * dim + 2 * cepstra + c] = static_cast<float>(delta2[(f + pad) * cepstra + c]);
    }
  return out;
}

}  // namespace kdspace_bench
