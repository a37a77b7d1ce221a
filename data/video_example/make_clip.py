"""Re-create ``taiji_640x360.mp4`` from the original HybrIK demo clip (see README.md).

    python data/video_example/make_clip.py PATH/TO/taiji.mp4

Frames 120-215 (96 frames, 4.0 s at 23.976 fps) of the 1280x720 original, resized to 640x360
with area interpolation and re-encoded by OpenCV as MPEG-4 Part 2 (``mp4v``) at the source
frame rate.
"""

import sys
from pathlib import Path

import cv2

FIRST, COUNT, SIZE = 120, 96, (640, 360)


def main(src: str) -> None:
    cap = cv2.VideoCapture(src)
    if not cap.isOpened():
        sys.exit(f'cannot open {src}')
    fps = cap.get(cv2.CAP_PROP_FPS)
    cap.set(cv2.CAP_PROP_POS_FRAMES, FIRST)
    out = Path(__file__).with_name('taiji_640x360.mp4')
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*'mp4v'), fps, SIZE)
    for _ in range(COUNT):
        ok, frame = cap.read()
        if not ok:
            sys.exit('source ended early')
        writer.write(cv2.resize(frame, SIZE, interpolation=cv2.INTER_AREA))
    writer.release()
    print(f'wrote {out} ({out.stat().st_size} bytes, {COUNT} frames at {fps:.3f} fps)')


if __name__ == '__main__':
    main(sys.argv[1] if len(sys.argv) > 1 else '../shared/data/videos/hybrik/taiji.mp4')
