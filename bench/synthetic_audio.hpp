// Synthetic audio for kdspace-bench's MFCC data sets (mfcc13, mfcc20): 16 kHz, a sequence of notes
// (0.08 to 0.6 s) played by 8 "instruments" (harmonic tones whose harmonic amplitudes fall off at
// different rates, with vibrato and an attack/decay envelope), some notes sounding two at a time,
// over a noise floor of varying level, with short silences. Its features come from mfcc()
// (audio_features.hpp), as those of the recordings do.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

#include "audio_features.hpp"

namespace kdspace_bench {

namespace synthetic_audio_detail {

constexpr double pi = 3.14159265358979323846;
constexpr double sample_rate = 16000;
constexpr std::size_t frame_length = 400, hop = 160;  // 25 ms and 10 ms at 16 kHz, as mfcc() frames

// Enough synthetic audio for `frames` frames of 25 ms every 10 ms (mfcc()).
inline std::vector<double> synth_audio(std::size_t frames, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  std::normal_distribution<double> normal(0, 1);
  const std::size_t samples = (frames - 1) * hop + frame_length;
  std::vector<double> audio(samples, 0.0);
  // Instruments: the rate at which harmonic amplitudes fall (1/h^rolloff), and the harmonics used.
  const double rolloff[8] = {0.6, 1.0, 1.5, 2.0, 2.5, 3.0, 1.2, 0.8};
  const int harmonics[8] = {12, 10, 8, 6, 5, 4, 9, 15};
  std::size_t at = 0;
  while (at < samples) {
    const std::size_t length = static_cast<std::size_t>((0.08 + 0.52 * unit(rng)) * sample_rate);
    const int voices = unit(rng) < 0.3 ? 2 : 1;
    const bool silence = unit(rng) < 0.1;
    for (int v = 0; v < voices && !silence; ++v) {
      const int instrument = static_cast<int>(rng() % 8);
      const double midi = 40 + std::floor(44 * unit(rng));
      const double f0 = 440 * std::pow(2, (midi - 69) / 12);
      const double gain = 0.2 + 0.8 * unit(rng);
      const double vibrato = 0.004 * unit(rng);
      for (std::size_t s = 0; s < length && at + s < samples; ++s) {
        const double t = static_cast<double>(s) / sample_rate;
        const double envelope = std::min(1.0, t / 0.01) * std::exp(-t * (1 + 0.5 * instrument));
        const double phase = 2 * pi * f0 * (t + vibrato * std::sin(2 * pi * 5 * t) / (2 * pi * 5));
        double value = 0;
        for (int h = 1; h <= harmonics[instrument] && f0 * h < 7900; ++h)
          value += std::sin(h * phase) / std::pow(static_cast<double>(h), rolloff[instrument]);
        audio[at + s] += gain * envelope * value;
      }
    }
    const double noise = std::pow(10, -3 + 2 * unit(rng));
    double smooth = 0;
    for (std::size_t s = 0; s < length && at + s < samples; ++s) {
      smooth = 0.7 * smooth + 0.3 * normal(rng);  // a little low-passed: more energy low
      audio[at + s] += noise * smooth;
    }
    at += length;
  }
  return audio;
}

}  // namespace synthetic_audio_detail

/// `frames` frames of `count` MFCCs each (no deltas; count <= 26, the mel bands), row-major, of
/// synthetic audio drawn with `seed`: the static features of speech and music retrieval.
inline std::vector<float> mfcc_static(std::size_t frames, std::uint32_t seed, std::size_t count) {
  using namespace synthetic_audio_detail;
  MfccShape shape;
  shape.cepstra = count;
  shape.deltas = false;
  return mfcc(synth_audio(frames, seed), sample_rate, shape);
}

}  // namespace kdspace_bench
