#!/usr/bin/python3
"""Find the moments in a collection of speech recordings where a given word is said.

Every recording is cut into 25 ms frames every 10 ms and each frame described by 13 MFCCs (mel
frequency cepstral coefficients); a moment is 9 consecutive frames (a 117-D vector, 0.11 s of
speech). All moments of all recordings go into one kdspace.KDTree. Each moment of the query word
then looks up its 50 nearest moments, and every neighbour votes for (its recording, its time minus
the query moment's time): where the word is really said, many moments of the query agree on one
recording and one time offset. Recordings are ranked by their best vote.

The recordings are real: the voice prompts of the Asterisk telephone system, one speaker, about
570 WAV files (Debian package asterisk-core-sounds-en-wav, downloaded and unpacked on first use;
see debian_data.py). Their file names say what they hold, so the answer can be checked by eye.

  PYTHONPATH=build/release/python /usr/bin/python3 examples/python/similar_moments.py number
  ... similar_moments.py minutes --approximate      (kdspace.Forest tuned to recall 0.9 instead)
  ... similar_moments.py WORD --recordings DIR      (your own folder of WAV files)
"""

import argparse
import collections
import glob
import os
import sys
import time

import numpy as np
from scipy.fft import dct
from scipy.io import wavfile

import kdspace

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import debian_data  # noqa: E402


def mfcc(signal, rate, mel_bands=26, coefficients=13, frame_s=0.025, hop_s=0.010):
    """MFCCs of a mono signal, one row per frame (pre-emphasis, Hann window, power spectrum, mel
    filter bank, log, DCT-II)."""
    signal = np.asarray(signal, dtype=np.float64)
    signal = np.append(signal[0], signal[1:] - 0.97 * signal[:-1])
    frame, hop = int(round(frame_s * rate)), int(round(hop_s * rate))
    if len(signal) < frame:
        return np.empty((0, coefficients))
    frames = np.lib.stride_tricks.sliding_window_view(signal, frame)[::hop] * np.hanning(frame)
    size = 1 << (frame - 1).bit_length()
    power = np.abs(np.fft.rfft(frames, size)) ** 2 / size

    def mel(f):
        return 2595 * np.log10(1 + f / 700)

    edges = 700 * (10 ** (np.linspace(0, mel(rate / 2), mel_bands + 2) / 2595) - 1)
    bins = np.floor((size + 1) * edges / rate).astype(int)
    bank = np.zeros((mel_bands, size // 2 + 1))
    for j in range(mel_bands):
        low, centre, high = bins[j], bins[j + 1], bins[j + 2]
        bank[j, low:centre] = (np.arange(low, centre) - low) / max(centre - low, 1)
        bank[j, centre:high] = (high - np.arange(centre, high)) / max(high - centre, 1)
    energies = np.log(np.maximum(power @ bank.T, 1e-10))
    return dct(energies, type=2, axis=1, norm="ortho")[:, :coefficients]


def moments(path, context=9):
    """The moments of one recording: `context` consecutive MFCC frames per row (the recording's mean
    removed: cepstral mean normalisation evens out its loudness and channel)."""
    rate, signal = wavfile.read(path)
    if signal.ndim > 1:
        signal = signal[:, 0]
    frames = mfcc(signal, rate)
    if len(frames) < context:
        return np.empty((0, context * 13), dtype=np.float32)
    frames -= frames.mean(axis=0)
    windows = np.lib.stride_tricks.sliding_window_view(frames, (context, frames.shape[1]))[:, 0]
    return windows.reshape(len(windows), -1).astype(np.float32)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("word", nargs="?", default="number", help="the recording to look for: WORD.wav")
    parser.add_argument("--recordings", help="a folder of WAV files (default: the Asterisk voice prompts)")
    parser.add_argument("--approximate", action="store_true", help="search a tuned kdspace.Forest instead")
    parser.add_argument("--top", type=int, default=10, help="recordings to list")
    args = parser.parse_args()

    files = (sorted(glob.glob(os.path.join(args.recordings, "**", "*.wav"), recursive=True)) if args.recordings
             else debian_data.speech_recordings())
    names = [os.path.relpath(f, os.path.commonpath(files)) for f in files]
    if args.word + ".wav" not in names:
        raise SystemExit(f"no recording {args.word}.wav among the {len(files)} recordings")

    started = time.perf_counter()
    parts = [moments(f) for f in files]
    data = np.concatenate(parts)
    owner = np.repeat(np.arange(len(files)), [len(p) for p in parts])
    start = np.arange(len(data)) - np.repeat(np.cumsum([0] + [len(p) for p in parts[:-1]]), [len(p) for p in parts])
    print(f"{len(files)} recordings, {len(data)} moments of {data.shape[1]} values "
          f"({time.perf_counter() - started:.1f} s to compute)")

    query = names.index(args.word + ".wav")
    own = np.flatnonzero(owner == query)
    started = time.perf_counter()
    if args.approximate:
        index = kdspace.Forest(data, trees=4)
        sample = data[np.random.default_rng(1).choice(len(data), 400, replace=False)]
        tuning = index.tune(0.9, k=50, queries=sample)
        chosen = (f"graph, ef {tuning['ef']}" if tuning["ef"] else
                  f"{tuning['trees']} trees, {tuning['checks']} checks")
        print(f"forest built and tuned: {chosen} "
              f"(recall@50 {tuning['validation_recall']:.2f} on held-out moments)")
    else:
        index = kdspace.KDTree(data)
    built = time.perf_counter()
    _, neighbours = index.query(data[own], k=50, workers=-1)
    print(f"index {built - started:.2f} s, {len(own)} queries {time.perf_counter() - built:.3f} s")

    # Votes: (recording, offset in steps of 50 ms) for every neighbour in another recording.
    votes = collections.Counter()
    for position, row in zip(own, neighbours):
        for j in row:
            if owner[j] != query:
                votes[owner[j], (start[j] - start[position]) // 5] += 1
    best = {}
    for (recording, offset), count in votes.items():
        if count > best.get(recording, (0, 0))[0]:
            best[recording] = (count, offset)
    print(f"\nwhere '{args.word}' is said (best vote per recording):")
    for recording, (count, offset) in sorted(best.items(), key=lambda kv: -kv[1][0])[:args.top]:
        print(f"  {names[recording]:45s} {count:4d} votes, at {max(offset, 0) * 0.05:5.2f} s")


if __name__ == "__main__":
    main()
