"""PNG writing of the default run plot: our `cosim.logs.plot.write_png` against Pillow (not a test).

`python3 benchmarks/bench_png.py [--repeat 20]`

The pixels are those of a real plot: the quick-start scenario is run once (into a temporary folder)
and its PNG read back. Each writer saves the same pixels to a file, fastest of `--repeat`; the
table gives ms per image, file size, and the ratio to Pillow at the same zlib level. Every file is
read back with Pillow and must hold exactly the same pixels. This is why the plot keeps its own
20-line writer beside Pillow: with no row filters it spends a fraction of Pillow's time on a mostly
flat-colour image, at a somewhat larger file.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from cosim.logs.plot import write_png  # noqa: E402

SCENARIO = "scenarios/warehouse_diff_drive_one_obstacle.toml"
DPI = 100.0


def _fastest(write, path: Path, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        write(path)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20, help="saves per writer; the fastest counts")
    arguments = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        run = [sys.executable, "-m", "cosim", "run", SCENARIO, "--quiet", "--out", str(scratch / "run.mcap")]
        subprocess.run(run, cwd=REPO, check=True)
        pixels = np.asarray(Image.open(scratch / "run.png").convert("RGB"))
        image = Image.fromarray(pixels)
        writers = {
            "write_png (ours: no row filter, zlib 1)": lambda p: write_png(p, pixels, DPI),
            "Pillow, compress_level=1": lambda p: image.save(p, compress_level=1, dpi=(DPI, DPI)),
            "Pillow, default (level 6)": lambda p: image.save(p, dpi=(DPI, DPI)),
        }
        rows = []
        for name, write in writers.items():
            path = scratch / "out.png"
            seconds = _fastest(write, path, arguments.repeat)
            same = np.array_equal(np.asarray(Image.open(path).convert("RGB")), pixels)
            rows.append((name, seconds, path.stat().st_size, same))
    pillow_fast = rows[1][1]
    height, width, _ = pixels.shape
    print(f"default plot of {SCENARIO}: {width} x {height} RGB, fastest of {arguments.repeat}\n")
    print("| writer | ms / image | vs Pillow level 1 | KiB | same pixels |")
    print("|---|---:|---:|---:|---|")
    for name, seconds, size, same in rows:
        print(f"| {name} | {seconds * 1e3:.1f} | {seconds / pillow_fast:.2f}x | {size / 1024:.0f} | {same} |")


if __name__ == "__main__":
    main()
