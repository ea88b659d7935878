"""Check what `make demo` produced, as CI does after running it: both metric rows printed, and the side-by-side
video exists, decodes, and has one frame per control step of the longer episode.

    python scripts/check_demo.py DEMO_OUTPUT.txt [VIDEO]

DEMO_OUTPUT.txt is what `make demo` printed (stdout); VIDEO defaults to renders/demo_required_sidestep.mp4.
Exit status 0 when everything holds, 1 with one line per problem otherwise.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

METHODS = ("cbf-only", "big-cbf")
T_C_S = 0.05            # the control period: the demo writes one frame per control step (20 fps)


def rows(text: str) -> dict[str, dict[str, str]]:
    """The metric rows of the demo's table: method -> {column: value}."""
    lines = text.splitlines()
    head = next((i for i, ln in enumerate(lines) if ln.split()[:2] == ["method", "success"]), None)
    if head is None:
        return {}
    keys = lines[head].split()
    out = {}
    for ln in lines[head + 1:]:
        vals = ln.split()
        if len(vals) != len(keys):
            break
        out[vals[0]] = dict(zip(keys, vals))
    return out


def decoded_frames(video: Path) -> tuple[int, tuple[int, int]]:
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(video))
    meta = next(reader)
    return sum(1 for _ in reader), tuple(meta["size"])


def main(argv: list[str]) -> int:
    if not argv or len(argv) > 2:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    text = Path(argv[0]).read_text()
    video = Path(argv[1] if len(argv) > 1 else "renders/demo_required_sidestep.mp4")
    problems = []
    table = rows(text)
    for m in METHODS:
        if m not in table:
            problems.append(f"no metric row for {m} in {argv[0]}")
    expected = max((round(float(r["time_s"]) / T_C_S) for r in table.values()), default=None)
    said = re.search(r"wrote (\S+) \((\d+) frames", text)
    if said is None:
        problems.append(f"the demo did not say where it wrote the video ({argv[0]})")
    if not video.is_file():
        problems.append(f"no video at {video}")
    else:
        try:
            n, size = decoded_frames(video)
        except Exception as exc:      # noqa: BLE001 -- any decoder failure is the finding
            problems.append(f"{video} does not decode: {exc}")
        else:
            if n == 0:
                problems.append(f"{video} has no frames")
            if said is not None and int(said.group(2)) != n:
                problems.append(f"the demo said {said.group(2)} frames, {video} decodes to {n}")
            if expected is not None and n != expected:
                problems.append(f"{video} has {n} frames, expected {expected} (the longer episode's control steps)")
            if not problems:
                print(f"demo ok: rows {', '.join(METHODS)}; {video}: {n} frames of {size[0]}x{size[1]}, decodes")
    for p in problems:
        print(p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
