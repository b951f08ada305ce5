"""Cost of Rerun logging per frame: ``python -m benchmarks.rerun_bench [BAG]``.

Logs the frames of a recorded run (default: the committed example bag) ``--repeat`` times into
a temporary .rrd with :class:`~fence_sorter.visualisation.rerun_log.RerunLogger`, as the live
child does, and prints the logging time per frame (best and median of ``--runs``) and the
.rrd size per frame, for each ``--scene-every`` batch size.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from benchmarks import REPO
from fence_sorter.visualisation.frames import bag_frames, scene_from_bag
from fence_sorter.visualisation.rerun_layout import open_recording
from fence_sorter.visualisation.rerun_log import RerunLogger


def bench(bag: Path, repeat: int, runs: int, scene_every: list[int]) -> list[str]:
    from fence_sorter.recording.bagread import read_bag  # lazy: loads rosbags

    contents = read_bag(bag)
    frames = list(bag_frames(contents)) * repeat
    scene = scene_from_bag(contents)
    parcels = sum(len(p) for _, _, p in frames) / max(len(frames), 1)
    lines = [f"{bag}: {len(frames)} frames, {parcels:.2f} parcels per frame"]
    with tempfile.TemporaryDirectory() as tmp:
        for every in scene_every:
            times = []
            size = 0
            for k in range(runs):
                out = Path(tmp) / f"bench_{every}_{k}.rrd"
                logger = RerunLogger(open_recording(out, scene=scene), scene, scene_every=every)
                t0 = time.perf_counter()
                for t, fence, ps in frames:
                    logger.log_frame(t, fence, ps)
                logger.flush()
                times.append((time.perf_counter() - t0) / len(frames) * 1e3)
                logger.close()
                size = out.stat().st_size
            lines.append(
                f"scene_every {every:4d}: {min(times):.3f} ms/frame best, "
                f"{statistics.median(times):.3f} median of {runs}; "
                f".rrd {size / len(frames) / 1e3:.2f} kB/frame"
            )
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="rerun_bench", description=__doc__.splitlines()[0])
    parser.add_argument("bag", nargs="?", default=str(REPO / "bags" / "example_4_parcels"))
    parser.add_argument("--repeat", type=int, default=3, help="frames of the bag, this often")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--scene-every", type=int, nargs="+", default=[1, 5, 25])
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.runs < 1 or min(args.scene_every) < 1:
        parser.error("--repeat, --runs and --scene-every must be >= 1")
    for line in bench(Path(args.bag), args.repeat, args.runs, args.scene_every):
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
