// Audio descriptors for the forest benchmark: MFCC frames (13 cepstral coefficients, their deltas
// and delta-deltas: 39 values a frame) computed from synthetic audio.
//
// The audio: 16 kHz, a sequence of notes (0.08 to 0.6 s) played by 8 "instruments" (harmonic tones
// whose harmonic amplitudes fall off at different rates, with vibrato and an attack/decay envelope),
// some notes sounding two at a time, over a noise floor of varying level, with short silences. The
// features: 25 ms Hamming-windowed frames every 10 ms, 512-point FFT power spectrum, 26 triangular
// mel filters (0 to 8 kHz), log energies, DCT-II (coefficients 0..12), and regression deltas over
// +-2 frames, twice.
#pragma once

#include <cmath>
#include <complex>
#include <cstddef>
#include <cstdint>
#include <random>
#include <vector>

namespace kdspace_bench {

inline constexpr std::size_t mfcc_dim = 39;

namespace audio_detail {

constexpr double pi = 3.14159265358979323846;
constexpr double sample_rate = 16000;
constexpr std::size_t frame_length = 400, hop = 160, fft_size = 512, mel_bands = 26, cepstra = 13;

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

// Enough synthetic audio for `frames` frames.
inline std::vector<double> synth_audio(std::size_t frames, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  std::normal_distribution<double> normal(0, 1);
  const std::size_t samples = frames * hop + frame_length;
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

}  // namespace audio_detail

/// `frames` MFCC frames (39 floats each, row-major) of synthetic audio drawn with `seed`.
inline std::vector<float> mfcc_frames(std::size_t frames, std::uint32_t seed) {
  using namespace audio_detail;
  const std::size_t pad = 4;  // frames each side, so that every output frame has full delta-deltas
  const std::size_t total = frames + 2 * pad;
  const std::vector<double> audio = synth_audio(total, seed);

  // Mel filterbank on the FFT bins.
  const std::size_t bins = fft_size / 2 + 1;
  std::vector<double> edges(mel_bands + 2);
  for (std::size_t i = 0; i < edges.size(); ++i)
    edges[i] = mel_to_hz(hz_to_mel(sample_rate / 2) * static_cast<double>(i) / static_cast<double>(mel_bands + 1));
  std::vector<double> filters(mel_bands * bins, 0.0);
  for (std::size_t b = 0; b < mel_bands; ++b)
    for (std::size_t j = 0; j < bins; ++j) {
      const double hz = static_cast<double>(j) * sample_rate / static_cast<double>(fft_size);
      const double rise = (hz - edges[b]) / (edges[b + 1] - edges[b]);
      const double fall = (edges[b + 2] - hz) / (edges[b + 2] - edges[b + 1]);
      filters[b * bins + j] = std::max(0.0, std::min(rise, fall));
    }

  std::vector<double> cepstrum(total * cepstra);
  std::vector<std::complex<double>> spectrum(fft_size);
  std::vector<double> log_energy(mel_bands);
  for (std::size_t f = 0; f < total; ++f) {
    std::fill(spectrum.begin(), spectrum.end(), 0.0);
    for (std::size_t s = 0; s < frame_length; ++s) {
      const double window = 0.54 - 0.46 * std::cos(2 * pi * static_cast<double>(s) / (frame_length - 1));
      spectrum[s] = window * audio[f * hop + s];
    }
    fft(spectrum);
    for (std::size_t b = 0; b < mel_bands; ++b) {
      double e = 0;
      for (std::size_t j = 0; j < bins; ++j) e += filters[b * bins + j] * std::norm(spectrum[j]);
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
  const std::vector<double> delta = deltas(cepstrum), delta2 = deltas(delta);
  std::vector<float> out(frames * mfcc_dim);
  for (std::size_t f = 0; f < frames; ++f)
    for (std::size_t c = 0; c < cepstra; ++c) {
      out[f * mfcc_dim + c] = static_cast<float>(cepstrum[(f + pad) * cepstra + c]);
      out[f * mfcc_dim + cepstra + c] = static_cast<float>(delta[(f + pad) * cepstra + c]);
      out[f * mfcc_dim + 2 * cepstra + c] = static_cast<float>(delta2[(f + pad) * cepstra + c]);
    }
  return out;
}

}  // namespace kdspace_bench
