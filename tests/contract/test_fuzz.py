"""The reliability probes of tools/fuzz.py, short (``make fuzz`` runs them long): every bus
decoder on random, cut, mutated, deeply nested and huge payloads; the SICK parser on mutated
telegrams and random bytes; the serial line unplugged and plugged back (issue 18)."""

from __future__ import annotations

import numpy as np
import pytest

from agent.bus.codecs import codec_for
from agent.bus.keys import STREAMS
from agent.bus.schemas import SCHEMAS
from knowledge.errors import ProtocolError
from tools.fuzz import SAMPLES, decoder_inputs, fuzz_decoders, fuzz_sick, replug_cycles, sample_payload

VIEW_ONLY = {"foxglove.SceneUpdate", "foxglove.FrameTransform"}  # encoded, never decoded


def test_the_samples_are_valid_messages_of_every_stream() -> None:
    rng = np.random.default_rng(0)
    for spec in STREAMS.values():
        data = sample_payload(spec.schema, rng)
        if spec.schema not in VIEW_ONLY:
            codec_for(spec.schema).decode(data)  # raises if the seed of the mutations is not valid
    assert set(SAMPLES) == {s.schema for s in STREAMS.values() if s.schema.startswith("loci.")}
    assert all(sid in SCHEMAS for sid in SAMPLES)


def test_every_bus_decoder_returns_a_message_or_a_protocol_error_on_any_input() -> None:
    report = fuzz_decoders(60, seed=1, huge_every=10)
    assert report["crashes"] == 0, report["examples"]
    assert report["inputs"] == 60 * len(STREAMS)
    for stream, counts in report["per_stream"].items():
        kinds = {k for k in counts if k.startswith("in:")}
        assert kinds == {"in:random", "in:truncated", "in:mutated", "in:nested", "in:huge", "in:valid"}, (
            stream
        )
        if STREAMS[stream].schema not in VIEW_ONLY:
            assert counts["decoded"] >= counts["in:valid"], (stream, counts)


@pytest.mark.parametrize(
    "schema", ["foxglove.LaserScan", "foxglove.PoseInFrame", "foxglove.CompressedImage", "loci.intent/1"]
)
def test_payloads_over_the_limits_are_refused_before_parsing(schema: str) -> None:
    rng = np.random.default_rng(2)
    huge = [data for kind, data in decoder_inputs(schema, 12, rng) if kind == "huge"]
    assert huge and all(len(h) > 8 << 20 for h in huge)
    for data in huge:
        with pytest.raises(ProtocolError, match="exceeds"):
            codec_for(schema).decode(data)


def test_sick_parser_gives_only_telegrams_that_were_on_the_line() -> None:
    report = fuzz_sick(4000, 4000, seed=3)
    assert report["crashes"] == 0 and report["bad_crc_out"] == 0, report["examples"]
    # the whole telegrams (a fifth) come out; flipped bits and cuts lose some
    assert report["telegrams_out"] >= report["mutations"]["whole"] > 0
    assert report["scans_decoded"] > 0


def test_serial_replug_resumes_within_two_seconds_every_time() -> None:
    report = replug_cycles(3, seed=4)
    assert report["missed"] == 0 and report["within_limit"] == report["cycles"] == 3, report
