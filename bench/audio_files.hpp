// Recordings for the benchmarks: MFCC frames (audio_features.hpp) of the speech and music that
// Debian packages ship, decoded with libsndfile (WAV, FLAC, Ogg Vorbis, MP3).
//
// bench/run_all.sh downloads the packages with `apt-get download` and unpacks them into the build
// folder (nothing is installed): asterisk-core-sounds-en-wav, a US English voice (Allison Smith)
// recorded for telephone prompts, 8 kHz; and asc-music, the soundtrack of the game Advanced
// Strategic Command, 44.1 kHz MP3.
#pragma once

#include <sndfile.h>

#include <algorithm>
#include <cstddef>
#include <dirent.h>
#include <stdexcept>
#include <string>
#include <vector>

#include "audio_features.hpp"

namespace kdspace_bench {

/// The files under `folder` (searched recursively) whose names end with `extension`, sorted.
inline std::vector<std::string> files_under(const std::string& folder, const std::string& extension) {
  std::vector<std::string> found;
  DIR* dir = opendir(folder.c_str());
  if (!dir) return found;
  while (const dirent* entry = readdir(dir)) {
    const std::string name = entry->d_name;
    if (name == "." || name == "..") continue;
    const std::string path = folder + "/" + name;
    if (entry->d_type == DT_DIR) {
      const std::vector<std::string> inner = files_under(path, extension);
      found.insert(found.end(), inner.begin(), inner.end());
    } else if (name.size() >= extension.size() &&
               name.compare(name.size() - extension.size(), extension.size(), extension) == 0) {
      found.push_back(path);
    }
  }
  closedir(dir);
  std::sort(found.begin(), found.end());
  return found;
}

/// The samples of an audio file, its channels averaged, and its sample rate.
inline std::vector<double> read_mono(const std::string& path, double& rate) {
  SF_INFO info{};
  SNDFILE* file = sf_open(path.c_str(), SFM_READ, &info);
  if (!file) throw std::runtime_error(path + ": " + sf_strerror(nullptr));
  const std::size_t channels = static_cast<std::size_t>(info.channels);
  std::vector<double> interleaved(4096 * channels), mono;
  for (;;) {
    const sf_count_t got = sf_readf_double(file, interleaved.data(), 4096);
    if (got <= 0) break;
    for (sf_count_t f = 0; f < got; ++f) {
      double sum = 0;
      for (std::size_t c = 0; c < channels; ++c) sum += interleaved[static_cast<std::size_t>(f) * channels + c];
      mono.push_back(sum / static_cast<double>(channels));
    }
  }
  sf_close(file);
  rate = info.samplerate;
  return mono;
}

/// The MFCC frames of every file, one after the other (row-major, shape.dim() floats each).
inline std::vector<float> mfcc_of_files(const std::vector<std::string>& paths, const MfccShape& shape) {
  std::vector<float> out;
  for (const std::string& path : paths) {
    double rate = 0;
    const std::vector<double> audio = read_mono(path, rate);
    const std::vector<float> frames = mfcc(audio, rate, shape);
    out.insert(out.end(), frames.begin(), frames.end());
  }
  return out;
}

}  // namespace kdspace_bench
