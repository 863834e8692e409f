"""Real data the examples use, taken from Debian packages without installing them: the package is
downloaded with `apt-get download` (the machine's apt lists must be up to date: `apt-get update`)
and unpacked into a cache folder ($KDSPACE_DATA, default ~/.cache/kdspace-examples)."""

import glob
import os
import subprocess
import tempfile


def cache_dir():
    return os.environ.get("KDSPACE_DATA", os.path.join(os.path.expanduser("~"), ".cache", "kdspace-examples"))


def package_files(package, pattern):
    """The files of a Debian package matching a glob pattern (inside the package's tree), unpacked
    once into the cache folder."""
    target = os.path.join(cache_dir(), package)
    found = sorted(glob.glob(os.path.join(target, pattern), recursive=True))
    if found:
        return found
    os.makedirs(target, exist_ok=True)
    with tempfile.TemporaryDirectory() as scratch:
        fetch = subprocess.run(["apt-get", "download", package], cwd=scratch, capture_output=True, text=True)
        debs = glob.glob(os.path.join(scratch, f"{package}_*.deb"))
        if fetch.returncode != 0 or not debs:
            raise SystemExit(f"could not download the Debian package {package} (apt-get download {package}: "
                             f"{fetch.stderr.strip() or 'no .deb'}); run `apt-get update` first, or give the "
                             "files on the command line")
        subprocess.run(["dpkg-deb", "-x", debs[0], target], check=True)
    found = sorted(glob.glob(os.path.join(target, pattern), recursive=True))
    if not found:
        raise SystemExit(f"the package {package} holds no files matching {pattern}")
    return found


def stereo_photographs():
    """The two views of the Middlebury "motorcycle" stereo pair that scikit-image ships
    (python3-skimage, skimage/data/motorcycle_left.png and motorcycle_right.png): rectified, so a
    true match lies on the same image row in both."""
    files = package_files("python3-skimage", "**/skimage/data/motorcycle_*.png")
    left = [f for f in files if f.endswith("motorcycle_left.png")]
    right = [f for f in files if f.endswith("motorcycle_right.png")]
    return left[0], right[0]


def speech_recordings():
    """About 570 voice prompts of the Asterisk telephone system, recorded by one speaker (Allison
    Smith), 8 kHz WAV files (asterisk-core-sounds-en-wav); their file names say what is said
    ("telephone-number.wav", "vm-minutes.wav", ...)."""
    return package_files("asterisk-core-sounds-en-wav", "usr/share/asterisk/sounds/en_US_f_Allison/**/*.wav")
