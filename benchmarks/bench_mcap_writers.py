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

    python3 -m benchmarks.bench_mcap_writers --goals [--steps 200000] [--scenarios a,b] [--repeat 1]

The logging goals of the sink change (issue 14), each measured with both writers in the same run:
`Recorder`'s file writer is `ChunkWriter` (ours, before) or `SdkWriter` (after: the same calls made
through foxglove-sdk's MCAP writer, `open_mcap` on the recorder's file, one `Channel.log` per
message, the chunk policy of ours: a chunk ends at 512 KiB of records or at a 0.5 s window of
simulated time, by `MCAPWriter.flush()`). Then
- (b) `bench_scenarios.part_b`: the two-FMU loop, every signal, steps/s (goal >= 50k);
- (c) `bench_scenarios.part_c`: each shipped scenario at full settings, real-time factor (goal >= 100x);
- reproducibility: one scenario run twice per writer, sha256 of the two logs equal or not;
- readers: the SDK's log read back by rosbags (every channel) and the mcap package (metadata,
  attachments);
- a killed run (`--parts k`): the quick-start scenario in a child process, SIGKILLed once it has
  logged 30 s of simulated time; `cosim log recover` on the cut file; the simulated time the
  recovered log reaches against the time the run had reached (a sink beside the writer reports it
  every 0.1 s of simulated time).
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


class SdkWriter:
    """`cosim.record.writer.ChunkWriter`'s interface, written through foxglove-sdk's MCAP writer.

    Schemas and channels become `foxglove.Schema` / `foxglove.Channel` of a private context with
    the MCAP sink (`open_mcap` on the recorder's open file); each message, packed records included,
    is one `Channel.log(payload, log_time=t)`. A chunk ends when 512 KiB of records are written
    (the SDK's `chunk_size`) or at the first message of a later window of simulated time
    (`flush()`), as ours."""

    def __init__(
        self, stream, chunk_size: int = 512 * 1024, compression_level: int = 3, chunk_duration_ns=None
    ):
        self._stream = stream
        self.chunk_size = chunk_size
        self.compression_level = compression_level
        self.chunk_duration_ns = chunk_duration_ns
        self._deadline = None
        self._schemas: dict[int, object] = {}
        self._channels: dict[int, object] = {}
        self._writer = None

    def start(self, profile: str, library: str) -> None:
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        import foxglove

        self._foxglove = foxglove
        self._context = foxglove.Context()
        options = MCAPWriteOptions(
            compression=MCAPCompression.Zstd,
            profile=profile,
            chunk_size=self.chunk_size,
            compression_level=self.compression_level,
        )
        self._writer = foxglove.open_mcap(self._stream, context=self._context, writer_options=options)

    def register_schema(self, name: str, encoding: str, data: bytes, schema_id: int | None = None) -> int:
        schema_id = schema_id if schema_id is not None else len(self._schemas) + 1
        self._schemas[schema_id] = self._foxglove.Schema(name=name, encoding=encoding, data=bytes(data))
        return schema_id

    def register_channel(self, topic, encoding, schema_id, metadata, channel_id=None) -> int:
        channel_id = channel_id if channel_id is not None else len(self._channels) + 1
        self._channels[channel_id] = self._foxglove.Channel(
            topic,
            schema=self._schemas[schema_id],
            message_encoding=encoding,
            context=self._context,
            metadata=dict(metadata),
        )
        return channel_id

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.write_metadata(name, dict(data))

    def add_attachment(self, create_time, log_time, name, media_type, data) -> None:
        self._writer.attach(
            log_time=log_time, create_time=create_time, name=name, media_type=media_type, data=bytes(data)
        )

    def _window(self, t_ns: int) -> None:
        if self.chunk_duration_ns:
            if self._deadline is not None and t_ns >= self._deadline:
                self._writer.flush()
                self._deadline = None
            if self._deadline is None:
                self._deadline = (t_ns // self.chunk_duration_ns + 1) * self.chunk_duration_ns

    def add_message(self, channel: int, t_ns: int, data: bytes, sequence: int = 0) -> None:
        self._window(t_ns)
        self._channels[channel].log(bytes(data), log_time=int(t_ns))

    def add_records(self, records: bytes, channels, times, offsets) -> None:
        """Records packed by the recorder (`cosim.record.batch`): each message's payload sliced out
        and logged on its channel (through the SDK's `BaseChannel.log`, skipping the Python
        wrapper's type checks: the fastest way the SDK offers)."""
        from cosim.record.mcap_format import MESSAGE_HEAD

        count = len(times)
        if count == 0:
            return
        starts = np.asarray(offsets, dtype=np.int64) + MESSAGE_HEAD.size
        ends = np.empty(count, dtype=np.int64)
        ends[:-1] = offsets[1:]
        ends[-1] = len(records)
        logs = {channel: self._channels[channel].base.log for channel in np.unique(channels).tolist()}
        window = self.chunk_duration_ns
        first = 0
        time_list = times.tolist()
        while first < count:
            stop = count
            if window:
                self._window(time_list[first])
                later = np.flatnonzero(np.asarray(times[first:]) >= self._deadline)
                if len(later):
                    stop = first + max(int(later[0]), 1)
            for channel, t_ns, begin, end in zip(
                channels[first:stop].tolist(),
                time_list[first:stop],
                starts[first:stop].tolist(),
                ends[first:stop].tolist(),
                strict=True,
            ):
                logs[channel](records[begin:end], t_ns, None)
            first = stop

    def flush(self) -> None:
        self._writer.flush()
        self._stream.flush()

    def hand_over(self) -> None:
        self._stream.flush()

    # The SDK writes a schema or channel when it is registered: none wait for a message.
    def has_definitions(self) -> bool:
        return False

    def take_definitions(self) -> list:
        return []

    def put_definitions(self, records: list) -> None:
        pass

    def finish(self) -> None:
        self._writer.close()
        self._stream.flush()


def _with_writer(writer_class):
    """A context in which `Recorder` writes its files with `writer_class`."""
    import contextlib

    from cosim.record import recorder

    @contextlib.contextmanager
    def patched():
        original = recorder.ChunkWriter
        recorder.ChunkWriter = writer_class
        try:
            yield
        finally:
            recorder.ChunkWriter = original

    return patched()


def _sha256(path: Path) -> str:
    import hashlib

    return hashlib.sha256(path.read_bytes()).hexdigest()


def _check_readers(path: Path) -> str:
    """Every channel decoded by rosbags; metadata and attachments read by the mcap package."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    decoded = 0
    with open(path, "rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        for schema in summary.schemas.values():
            sections = schema.data.decode().split("=" * 80 + "\n")
            types = dict(get_types_from_msg(sections[0], schema.name))
            for section in sections[1:]:
                header, _, body = section.partition("\n")
                types.update(get_types_from_msg(body, header.removeprefix("MSG: ").strip()))
            store.register({key: value for key, value in types.items() if key not in store.fielddefs})
        for schema, _, message in reader.iter_messages():
            store.deserialize_cdr(message.data, schema.name)
            decoded += 1
        metadata = [item.name for item in reader.iter_metadata()]
        attachments = [item.name for item in reader.iter_attachments()]
    return f"{decoded} messages decoded, metadata {metadata}, attachments {attachments}"


def goals(steps: int, scenarios: list[str] | None, repeat: int, parts: str = "b,c,r,k") -> None:
    """The sink change's goals, ours (ChunkWriter) against foxglove-sdk (SdkWriter), same run."""

    from cosim.record.writer import ChunkWriter

    writers = {"ours": ChunkWriter, "foxglove-sdk": SdkWriter}
    if "b" in parts:
        _goal_b(writers, steps, repeat)
    if "c" in parts:
        _goal_c(writers, scenarios, repeat)
    if "r" in parts:
        _goal_reproducible(writers)
    if "k" in parts:
        _goal_killed(writers)


class _Progress:
    """A recorder sink that prints the log time reached, every 0.1 s of simulated time."""

    def __init__(self) -> None:
        self.last = -1

    def channel(self, *args) -> None:
        pass

    def message(self, channel_id: int, t_ns: int, payload: bytes) -> None:
        if t_ns // 100_000_000 > self.last:
            self.last = t_ns // 100_000_000
            sys.stdout.write(f"{t_ns}\n")
            sys.stdout.flush()


def _killed_child(writer_name: str, path: str) -> None:
    """The child of `_goal_killed`: the quick-start run, logging with `writer_name`'s writer."""
    import dataclasses

    from benchmarks.bench_scenarios import REPO
    from cosim.navigation.run import run_scenario
    from cosim.record.writer import ChunkWriter
    from cosim.scenario.load import load_scenario

    scenario = load_scenario(REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml")
    writer = {"ours": ChunkWriter, "foxglove-sdk": SdkWriter}[writer_name]
    with _with_writer(writer):
        run_scenario(dataclasses.replace(scenario, plot=False), Path(path), sink=_Progress())


def _goal_killed(writers) -> None:
    import subprocess

    from cosim.logs.recover import recover_log

    print("killed run: quick-start scenario, SIGKILL after 30 s simulated, then cosim log recover")
    with tempfile.TemporaryDirectory() as scratch:
        for name in writers:
            log = Path(scratch) / f"killed-{name}.mcap"
            command = [sys.executable, "-m", "benchmarks.bench_mcap_writers", "--killed-child", name]
            command.append(str(log))
            child = subprocess.Popen(command, stdout=subprocess.PIPE, text=True)
            reached = 0
            for line in child.stdout:
                reached = int(line)
                if reached >= 30_000_000_000:
                    child.kill()
                    break
            child.wait()
            recovery = recover_log(log, Path(scratch) / f"recovered-{name}.mcap")
            lost = reached / 1e9 - recovery.end_time
            print(
                f"  {name:<13} run reached {reached / 1e9:.2f} s, recovered log ends at "
                f"{recovery.end_time:.2f} s: {lost:.2f} s lost ({recovery.messages} messages, "
                f"{recovery.chunks_copied} chunks copied, {recovery.chunks_rebuilt} rebuilt)"
            )


def _goal_b(writers, steps: int, repeat: int) -> None:
    from benchmarks.bench_scenarios import part_b

    print("(b) two-FMU loop, every signal (goal >= 50k steps/s), fastest of", repeat)
    # Wall steps/s as part (b) times it; and steps per CPU second of the whole process (the SDK's
    # compression threads included) in `Master.run_recorded`, the timed loop (the log's close not
    # included): less sensitive to other processes' load than the wall clock.
    from cosim.core.master import Master

    rates, cpu_rates = {}, {}
    run_recorded = Master.run_recorded
    spent = [0.0]

    def timed(self, count, *args, **kwargs):
        started = time.process_time()
        try:
            return run_recorded(self, count, *args, **kwargs)
        finally:
            if count > 1:
                spent[0] += time.process_time() - started

    Master.run_recorded = timed
    try:
        for _ in range(repeat):
            for name, writer in writers.items():
                spent[0] = 0.0
                with _with_writer(writer):
                    rate = part_b(steps)[0].rate
                rates[name] = max(rates.get(name, 0.0), rate)
                cpu_rates[name] = max(cpu_rates.get(name, 0.0), (steps - 1) / spent[0])
    finally:
        Master.run_recorded = run_recorded
    for name, rate in rates.items():
        print(
            f"  {name:<13} {rate:12,.0f} steps/s wall  {cpu_rates[name]:12,.0f} steps per CPU s"
            f"  {'holds' if rate >= 50_000 else 'FAILS'}"
        )
    print(
        f"  sdk / ours: wall {rates['foxglove-sdk'] / rates['ours']:.2f}, "
        f"CPU {cpu_rates['foxglove-sdk'] / cpu_rates['ours']:.2f}"
    )


def _goal_c(writers, scenarios, repeat: int) -> None:
    import dataclasses

    from benchmarks.bench_scenarios import REPO
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    paths = sorted((REPO / "scenarios").glob("*.toml"))
    if scenarios:
        paths = [path for path in paths if path.stem in scenarios]
    print("(c) shipped scenarios, full logging (goal >= 100x real time), fastest of", repeat)
    with tempfile.TemporaryDirectory() as scratch:
        for path in paths:
            scenario = dataclasses.replace(load_scenario(path), plot=False)
            factors, outcomes = {}, {}
            for k in range(repeat):
                for name, writer in writers.items():
                    with _with_writer(writer):
                        result = run_scenario(scenario, Path(scratch) / f"{name}{k}.mcap", force=True)
                    factors[name] = max(factors.get(name, 0.0), result.real_time_factor)
                    outcomes[name] = (result.outcome.time, result.outcome.distance)
            same = (
                "same outcome"
                if outcomes["ours"] == outcomes["foxglove-sdk"]
                else f"OUTCOMES DIFFER {outcomes}"
            )
            verdicts = {name: "holds" if factor >= 100 else "FAILS" for name, factor in factors.items()}
            print(
                f"  {path.stem:<40} ours {factors['ours']:6.0f}x ({verdicts['ours']})"
                f"  sdk {factors['foxglove-sdk']:6.0f}x ({verdicts['foxglove-sdk']})"
                f"  sdk/ours {factors['foxglove-sdk'] / factors['ours']:.2f}  {same}"
            )


def _goal_reproducible(writers) -> None:
    import dataclasses

    from benchmarks.bench_scenarios import REPO
    from cosim.navigation.run import run_scenario
    from cosim.scenario.load import load_scenario

    with tempfile.TemporaryDirectory() as scratch:
        scenario = dataclasses.replace(
            load_scenario(
                REPO / "scenarios" / "warehouse_diff_drive_one_obstacle.toml", ["simulation.stop_time=20"]
            ),
            plot=False,
        )
        print("reproducibility: warehouse_diff_drive_one_obstacle, 20 s, run twice per writer")
        for name, writer in writers.items():
            logs = []
            for k in range(2):
                log = Path(scratch) / f"same-{name}-{k}.mcap"
                with _with_writer(writer):
                    run_scenario(scenario, log, force=True)
                logs.append(log)
            a, b = _sha256(logs[0]), _sha256(logs[1])
            verdict = "same sha256" if a == b else f"DIFFERENT sha256 ({a[:12]} vs {b[:12]})"
            print(f"  {name:<13} {verdict}; {logs[0].stat().st_size / 1e6:.2f} MB")
            print(f"  {name:<13} readers: {_check_readers(logs[0])}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--messages", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--goals", action="store_true", help="measure the sink change's goals (above)")
    parser.add_argument("--steps", type=int, default=200_000, help="--goals: macro steps of part (b)")
    parser.add_argument(
        "--parts", default="b,c,r,k", help="--goals: b, c, r (reproducibility and readers), k (killed run)"
    )
    parser.add_argument("--killed-child", nargs=2, metavar=("WRITER", "LOG"), help=argparse.SUPPRESS)
    parser.add_argument("--scenarios", help="--goals: comma-separated scenario names (default: all shipped)")
    args = parser.parse_args(argv)
    try:
        import foxglove  # noqa: F401
    except ImportError:
        print("bench_mcap_writers: skipped (foxglove-sdk is not installed)")
        return 0
    if args.killed_child:
        _killed_child(*args.killed_child)
        return 0
    if args.goals:
        goals(args.steps, args.scenarios.split(",") if args.scenarios else None, args.repeat, args.parts)
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
