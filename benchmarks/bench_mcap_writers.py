"""MCAP write throughput: navcosim's ChunkWriter against foxglove-sdk's writer (Channel.log).

    python3 -m benchmarks.bench_mcap_writers [--messages 100000] [--repeat 3]

The same interleaved stream is written three ways, interleaved per repeat, fastest of --repeat:
- floor: each message's bytes written to a buffered file as they are (no records, no index);
- ours: `cosim.record.writer.ChunkWriter.add_message` per message (zstd level 3, 512 KiB chunks,
  message indexes, summary), the recorder's per-message path (the run loop batches most messages
  through `add_records`, not measured here);
- foxglove: `foxglove.open_mcap` + `Channel.log(payload, log_time=...)` per message (zstd level 3,
  512 KiB chunks; compression threads at the SDK default, one per physical CPU), and `foxglove1`
  the same with compression in the logging thread (`compression_threads=0`).
Three channels with payload sizes of a run's /odom (~700 B), /scan (360 beams, ~1.5 KB) and a
component's signals (~100 B), in the run's proportions (5 : 1 : 10). Prints messages/s, MB/s of
payload and each writer's time as a ratio to the floor; file sizes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = {"/odom": 724, "/scan": 1508, "/signals/vehicle": 96}
WEIGHTS = {"/odom": 5, "/scan": 1, "/signals/vehicle": 10}


def _stream(count: int) -> list[tuple[str, int, bytes]]:
    rng = np.random.default_rng(1)
    topics = [topic for topic, weight in WEIGHTS.items() for _ in range(weight)]
    # Compressible like real CDR (mostly small floats and zeros), not random bytes.
    base = {topic: rng.normal(size=size // 8).astype("<f8").tobytes()[:size] for topic, size in SIZES.items()}
    out = []
    for k in range(count):
        topic = topics[k % len(topics)]
        payload = bytearray(base[topic])
        payload[:8] = np.int64(k).tobytes()
        out.append((topic, k * 1_000_000, bytes(payload)))
    return out


def _floor(stream, path: Path) -> None:
    with open(path, "wb") as handle:
        for _, _, payload in stream:
            handle.write(payload)


def _ours(stream, path: Path) -> None:
    from cosim.record.writer import ChunkWriter

    with open(path, "wb") as handle:
        writer = ChunkWriter(handle, chunk_size=512 * 1024, compression_level=3)
        writer.start(profile="ros2", library="bench")
        channels, sequences = {}, {}
        for topic in SIZES:
            schema = writer.register_schema(topic.strip("/").replace("/", "_"), "ros2msg", b"uint8[] data")
            channels[topic] = writer.register_channel(topic, "cdr", schema, {})
            sequences[topic] = 0
        for topic, t_ns, payload in stream:
            writer.add_message(channels[topic], t_ns, payload, sequences[topic])
            sequences[topic] += 1
        writer.finish()


def _foxglove(stream, path: Path, threads: int | None = None) -> None:
    from foxglove.mcap import MCAPCompression, MCAPWriteOptions

    import foxglove

    context = foxglove.Context()
    options = MCAPWriteOptions(
        compression=MCAPCompression.Zstd,
        chunk_size=512 * 1024,
        compression_level=3,
        compression_threads=threads,
    )
    writer = foxglove.open_mcap(path, allow_overwrite=True, context=context, writer_options=options)
    channels = {
        topic: foxglove.Channel(
            topic,
            schema=foxglove.Schema(
                name=topic.strip("/").replace("/", "_"), encoding="ros2msg", data=b"uint8[] data"
            ),
            message_encoding="cdr",
            context=context,
        )
        for topic in SIZES
    }
    for topic, t_ns, payload in stream:
        channels[topic].log(payload, log_time=t_ns)
    writer.close()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    try:
        import foxglove  # noqa: F401
    except ImportError:
        print("bench_mcap_writers: skipped (foxglove-sdk is not installed)")
        return 0
    stream = _stream(args.messages)
    payload_mb = sum(len(payload) for _, _, payload in stream) / 1e6
    writers = {
        "floor": _floor,
        "ours": _ours,
        "foxglove": _foxglove,
        "foxglove1": lambda stream, path: _foxglove(stream, path, threads=0),
    }
    best = {name: float("inf") for name in writers}
    sizes = {}
    with tempfile.TemporaryDirectory() as folder:
        for _ in range(args.repeat):
            for name, write in writers.items():
                path = Path(folder) / f"{name}.mcap"
                started = time.perf_counter()
                write(stream, path)
                best[name] = min(best[name], time.perf_counter() - started)
                sizes[name] = path.stat().st_size
    print(f"{args.messages} messages, {payload_mb:.1f} MB of payload, fastest of {args.repeat}")
    print("writer      time [s]   messages/s   MB/s   x floor   file [MB]")
    for name, seconds in best.items():
        print(
            f"{name:<10} {seconds:9.3f} {args.messages / seconds:12.0f} {payload_mb / seconds:6.0f}"
            f" {seconds / best['floor']:9.1f} {sizes[name] / 1e6:11.2f}"
        )
    print(
        f"ours / foxglove: {best['ours'] / best['foxglove']:.2f}, ours / foxglove1: "
        f"{best['ours'] / best['foxglove1']:.2f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
