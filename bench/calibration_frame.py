"""The calibration frame of a clip (issue 61 item 3): ``pipeline.neutral.pick_neutral`` on the
real clip, every candidate's score and its parts (the curve fit's weights, the jaw, MediaPipe's
eyeBlink), and the frame picked.

    python bench/calibration_frame.py [--clip ../shared/data/real/video/single_face.mp4]
                                      [--frames START:STOP] [--json bench/figures/calibration_frame.json]
"""
import argparse
from pathlib import Path

import invface
from invface.pipeline.clips import open_clip
from invface.pipeline.neutral import pick_neutral

from _common import shared, write_json


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clip", type=Path)
    ap.add_argument("--frames", help="the selection to look in (default: the whole clip)")
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    clip = open_clip(a.clip or shared("real", "video", "single_face.mp4", what="the real clip"), a.frames)
    model = invface.template.build()
    lines = []

    def progress(event):
        if "message" in event:
            lines.append(event["message"])
            print(event["message"], flush=True)
    chosen, why, _ = pick_neutral(model, clip, progress=progress,
                                  over="the selected frames" if a.frames else "the whole shot")
    frame = chosen.frame
    print(f"picked {frame.name}: {why}")
    write_json(a.json, {"clip": str(clip.source), "frames": a.frames, "picked": frame.name, "why": why,
                        "candidates": lines})


if __name__ == "__main__":
    main()
