#!/usr/bin/env bash
# The README's animated preview (docs/img/demo.gif) from the demo's video: `make demo` first, then this.
# 12 s from t = 1 s, 5 frames per second, 560 px wide, one 128-colour palette (the overlay colours survive it).
set -euo pipefail
cd "$(dirname "$0")/.."
video=${1:-renders/demo_required_sidestep.mp4}
ff=$(.venv/bin/python -c "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())")
mkdir -p docs/img
"$ff" -y -loglevel error -ss 1 -t 12 -i "$video" \
    -vf "fps=5,scale=560:-1:flags=lanczos,split[a][b];[a]palettegen=max_colors=128[p];[b][p]paletteuse=dither=none" \
    docs/img/demo.gif
echo "wrote docs/img/demo.gif ($(stat -c %s docs/img/demo.gif) bytes)"
