"""`cosim.core.gather.make_gather` against the connection's definition applied link by link (input =
output * scale + offset; a plain copy a copy, bit for bit), for wirings that take each of its
paths: per-value copies, NumPy index copies, and slice copies of consecutive or evenly spaced
outputs (a planner's interleaved path, a lidar's scan)."""

from __future__ import annotations

import numpy as np
import pytest
from fixtures.links import Box, linked_inputs

from cosim.core.gather import Snapshot, _runs, make_gather
from cosim.core.system import System


def _interleaved(n: int) -> list[tuple[int, int]]:
    """A pose then x, y pairs: out 1..3 -> in 1..3, out 4, 6, ... -> in 4.., out 5, 7, ... -> in 4 + n.."""
    pairs = [(i, i) for i in range(3)]
    for k in range(n):
        pairs += [(3 + 2 * k, 3 + k), (4 + 2 * k, 3 + n + k)]
    return pairs


def _scan(n: int) -> list[tuple[int, int]]:
    """Two arrays of n, interleaved in connection order: out i -> in i, out n + i -> in 2n + i."""
    return [pair for i in range(n) for pair in ((i, i), (n + i, 2 * n + i))]


WIRINGS = {
    "scalar": [(0, 2), (1, 0)],
    "interleaved_path": _interleaved(40),
    "scan": _scan(30),
    "reversed": [(i, 19 - i) for i in range(20)],
    "scattered": [(i, (7 * i) % 23) for i in range(23)],
    "consecutive_runs": [(i, i) for i in range(5)] + [(10 + i, 5 + i) for i in range(5)],
}


@pytest.mark.parametrize("wiring", sorted(WIRINGS))
@pytest.mark.parametrize(
    "scale_offset", [(1.0, 0.0), (-0.5, 0.0), (2.0, 0.25)], ids=["copy", "scaled", "affine"]
)
def test_gather_matches_the_connections_copied_one_by_one(wiring, scale_offset):
    pairs = WIRINGS[wiring]
    outputs = max(o for o, _ in pairs) + 1
    inputs = max(i for _, i in pairs) + 3  # two inputs left unconnected: keep their start value
    system = System(0.1)
    source = system.add(Box("source", outputs=outputs))
    sink = system.add(Box("sink", inputs=inputs))
    scale, offset = scale_offset
    for out, into in pairs:
        system.connect(f"source.out[{out + 1}]", f"sink.in[{into + 1}]", scale=scale, offset=offset)
    rng = np.random.default_rng(len(pairs))
    source.output_buffer[:] = rng.normal(size=outputs) * 10.0 ** rng.integers(-300, 300, size=outputs)
    source.output_buffer[0] = -0.0
    source.output_buffer[-1] = np.nan
    gather = make_gather(system, sink)
    assert gather is not None
    for _ in range(2):  # again after the outputs changed: the gather reads the buffers anew
        expected = linked_inputs(system, sink)
        gather()
        assert sink.input_buffer.tobytes() == expected.tobytes()
        source.output_buffer[:] = source.output_buffer[::-1] * 3.0


def test_an_interleaved_path_and_a_scan_are_copied_as_a_few_slices():
    """The wirings above that the slice path takes (so the test above checks it): (source start,
    stride, target start, length) per stretch; scattered inputs take the index copy."""

    def runs(name):
        pairs = np.array(WIRINGS[name])
        return _runs(pairs[:, 0], pairs[:, 1])

    assert runs("interleaved_path") == [(0, 1, 0, 4), (5, 2, 4, 39), (4, 2, 43, 40)]
    assert runs("scan") == [(0, 1, 0, 30), (30, 1, 60, 30)]
    assert runs("consecutive_runs") == [(0, 1, 0, 5), (10, 1, 5, 5)]
    assert runs("scattered") is None
    assert runs("reversed") is None


def test_a_snapshot_gathers_plain_links_from_many_producers_as_taken():
    """Two values from each of five producers into one consumer, through one snapshot: the values
    at `take` (not those written after it), each link's output into its input."""
    system = System(0.1)
    producers = [system.add(Box(f"p{k}", outputs=3)) for k in range(5)]
    sink = system.add(Box("sink", inputs=12))
    wired = []
    for k in range(5):
        for out, into in ((0, 2 * k), (2, 2 * k + 1)):
            system.connect(f"p{k}.out[{out + 1}]", f"sink.in[{into + 1}]")
            wired.append((k, out, into))
    for k, producer in enumerate(producers):
        producer.output_buffer[:] = [k + 0.25, -0.0 if k == 2 else k + 0.5, k + 0.75]
    snapshot = Snapshot(producers[::-1])  # any order of producers
    gather = snapshot.gather(sink, system.links()["sink"])
    snapshot.take()
    expected = sink.input_buffer.copy()
    for k, out, into in wired:
        expected[into] = producers[k].output_buffer[out]
    for producer in producers:  # after the snapshot: not seen until the next `take`
        producer.output_buffer[:] = 99.0
    gather()
    assert sink.input_buffer.tobytes() == expected.tobytes()
    assert sink.input_buffer[10:].tolist() == [-7.0, -7.0]  # unconnected: start values
    snapshot.take()
    gather()
    assert sink.input_buffer[:10].tolist() == [99.0] * 10


def test_a_snapshot_refuses_a_scaled_link():
    system = System(0.1)
    producer = system.add(Box("p", outputs=1))
    sink = system.add(Box("sink", inputs=1))
    system.connect("p.out[1]", "sink.in[1]", scale=2.0)
    with pytest.raises(ValueError, match="plain copies only"):
        Snapshot([producer]).gather(sink, system.links()["sink"])


@pytest.mark.parametrize("seed", range(20))
def test_shuffled_strided_stretches_are_found_as_they_were_made(seed):
    """Random wirings of one to five stretches (consecutive inputs from outputs at a stride), apart
    from each other, in shuffled connection order: the stretches found are those made (up to four;
    five: None, an index copy)."""
    rng = np.random.default_rng(seed)
    made, pairs, target = [], [], 0
    for _ in range(1 + seed % 5):
        length, stride, start = int(rng.integers(2, 30)), int(rng.integers(1, 4)), int(rng.integers(0, 50))
        made.append((start, stride, target, length))
        pairs += [(start + stride * i, target + i) for i in range(length)]
        target += length + int(rng.integers(1, 3))  # a gap: the next stretch is another
    rng.shuffle(pairs)
    sources, targets = np.array(pairs).T
    assert _runs(sources, targets) == (made if len(made) <= 4 else None)
