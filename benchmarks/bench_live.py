"""Pacing of `cosim run --live --realtime R`: does simulated time pass at R x the wall clock?

    python3 -m benchmarks.bench_live [--stop-time 20] [--realtime 1 2]

The quick-start scenario, cut at --stop-time simulated seconds, runs three ways, each in a fresh
process: unpaced (`cosim run`, the floor: start-up plus computing), and `--live --realtime R` for each
R with a WebSocket client (foxglove.sdk.v1) subscribed to /odom. Printed per R:
- process ratio: the paced process's wall time x R / simulated time (start-up included, so a
  little above 1 even with exact pacing; the unpaced run's wall time is printed as the reference);
- stream ratio: (wall time between the first and the last /odom message the client received) x R /
  (simulated time between them); 1.00 is exact pacing.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "warehouse_diff_drive_one_obstacle.toml"


async def _odom_times(url: str) -> list[tuple[float, int]]:
    """(wall clock [s], stamp [ns]) of every /odom message received until the server stops."""
    import websockets

    received: list[tuple[float, int]] = []
    subscribed: dict[int, dict] = {}
    async with websockets.connect(url, subprotocols=["foxglove.sdk.v1"], max_size=None) as client:
        try:
            async for frame in client:
                if isinstance(frame, bytes):
                    if frame[0] == 1:
                        received.append((time.perf_counter(), struct.unpack_from("<IQ", frame, 1)[1]))
                    continue
                message = json.loads(frame)
                if message["op"] == "advertise":
                    for channel in message["channels"]:
                        if channel["topic"] == "/odom":
                            subscribed[channel["id"]] = {"id": 1, "channelId": channel["id"]}
                            await client.send(
                                json.dumps({"op": "subscribe", "subscriptions": [subscribed[channel["id"]]]})
                            )
                elif message["op"] == "status" and message["message"].startswith("Unknown channel ID"):
                    await asyncio.sleep(0.02)  # the SDK's table lagged the advertise: again
                    channel_id = int(message["message"].rsplit(":", 1)[1])
                    if channel_id in subscribed:
                        await client.send(
                            json.dumps({"op": "subscribe", "subscriptions": [subscribed[channel_id]]})
                        )
        except websockets.ConnectionClosed:
            pass
    return received


def _command(stop_time: float, extra: list[str]) -> list[str]:
    return [
        sys.executable, "-m", "cosim", "run", str(SCENARIO), "--out", "/dev/null", "--no-plot", "--quiet",
        "--set", f"simulation.stop_time={stop_time:g}", *extra,
    ]  # fmt: skip


def _unpaced(stop_time: float) -> float:
    started = time.perf_counter()
    subprocess.run(_command(stop_time, []), cwd=ROOT, check=False, capture_output=True)
    return time.perf_counter() - started


def _paced(stop_time: float, realtime: float) -> tuple[float, list[tuple[float, int]]]:
    extra = ["--live", "--port", "0", "--realtime", f"{realtime:g}", "--linger", "0"]
    started = time.perf_counter()
    process = subprocess.Popen(_command(stop_time, extra), cwd=ROOT, stderr=subprocess.PIPE, text=True)
    url = process.stderr.readline().split()[2]
    received = asyncio.run(_odom_times(url))
    process.stderr.read()
    process.wait()
    return time.perf_counter() - started, received


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stop-time", type=float, default=20.0, help="simulated seconds per run (20)")
    parser.add_argument("--realtime", type=float, nargs="+", default=[1.0], help="R values (1)")
    args = parser.parse_args(argv)
    try:
        import websockets  # noqa: F401

        import foxglove  # noqa: F401
    except ImportError as error:
        print(f"bench_live: skipped ({error.name} is not installed)")
        return 0
    floor = _unpaced(args.stop_time)
    print(f"quick-start scenario, {args.stop_time:g} s simulated; unpaced run: {floor:.2f} s wall")
    print("    R  process [s]  process ratio  /odom msgs  stream [s]  simulated [s]  stream ratio")
    for realtime in args.realtime:
        wall, received = _paced(args.stop_time, realtime)
        process_ratio = wall * realtime / args.stop_time
        if len(received) < 2:
            print(
                f"{realtime:5g}  {wall:11.2f}  {process_ratio:13.3f}  {len(received):10d}  (too few messages)"
            )
            continue
        span_wall = received[-1][0] - received[0][0]
        span_sim = (received[-1][1] - received[0][1]) / 1e9
        print(
            f"{realtime:5g}  {wall:11.2f}  {process_ratio:13.3f}  {len(received):10d}  {span_wall:10.2f}"
            f"  {span_sim:13.2f}  {span_wall * realtime / span_sim:12.3f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
