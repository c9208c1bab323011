"""Temperatures command 0xD1: byte layout, checksum, conversion to deg C, stream framing."""

from imu_allan.device import gx3_protocol as p
from imu_allan.device.gx3_stream import StreamParser
import numpy as np
import pytest


def test_worked_example_bytes():
    """Reply layout of DCP-GX3 6.7, worked by hand: D1, 4 x u16 BE, u32 BE timer, u16 sum."""
    # 0xD1 + 085B 0800 0834 07C6 + 00098968 (625000 ticks); sum of those 13 bytes = 831.
    expected = bytes.fromhex('D1 085B 0800 0834 07C6 00098968 033F')
    assert p.encode_temperature_reply((2139, 2048, 2100, 1990), 625000) == expected
    assert p.REPLY_LENGTHS[p.TEMPERATURES] == len(expected) == 15
    got = p.decode_temperature_reply(expected)
    assert got.counts == (2139, 2048, 2100, 1990) and got.timer == 625000
    assert p.cmd_temperatures() == b'\xD1' == p.cmd_poll(p.TEMPERATURES)
    assert p.COMMAND_LENGTHS[p.TEMPERATURES] == 1


def test_decoder_refuses_damage():
    """A flipped byte fails the checksum; a wrong header or length is refused."""
    good = p.encode_temperature_reply((1, 2, 3, 4), 2**32 + 5)   # timer wraps to 5
    assert p.decode_temperature_reply(good).timer == 5
    bad = bytearray(good)
    bad[4] ^= 0x10
    with pytest.raises(ValueError, match='checksum'):
        p.decode_temperature_reply(bytes(bad))
    with pytest.raises(ValueError, match='not a 0xD1'):
        p.decode_temperature_reply(good[:-1])
    with pytest.raises(ValueError):
        p.encode_temperature_reply((1, 2, 3), 0)
    with pytest.raises(ValueError):
        p.encode_temperature_reply((1, 2, 3, 70000), 0)


def test_conversion_against_the_reference_formulas():
    """
    Eq. 15 (exact form) at a hand-worked code, and Eq. 16 (linear) over -40..85 deg C.

    2139 counts: V = 1.56665 V, sqrt(2.1962e6 + 0.29725 / 3.88e-6) = 1507.584 -> 25.624 deg C.
    The linear approximation is a different formula from the same manual; the two agree to
    0.7 deg C over the calibrated range (the curvature of Eq. 15).
    """
    assert p.counts_to_celsius(2139) == pytest.approx(25.624, abs=1e-3)
    assert p.Temperatures((2139, 0, 0, 0), 0).celsius == p.counts_to_celsius(2139)
    codes = np.arange(4096)
    exact = p.counts_to_celsius(codes)
    linear = -((3.0 * codes / 4096) - 1.8583) / 11.67e-3
    inside = (exact >= -40) & (exact <= 85)
    assert inside.sum() > 1800
    assert np.max(np.abs(exact - linear)[inside]) < 0.7
    assert np.all(np.diff(exact) < 0), 'counts fall as the temperature rises'


def test_inverse_round_trip():
    """celsius_to_counts is the nearest code: round trip within half a count's step."""
    temps = np.linspace(-40, 85, 1001)
    codes = p.celsius_to_counts(temps)
    back = p.counts_to_celsius(codes)
    step = np.abs(p.counts_to_celsius(codes + 1) - back)
    assert np.all(np.abs(back - temps) <= 0.5 * step + 1e-9)
    assert p.celsius_to_counts(25.0) in (2148, 2149, 2150)
    assert p.celsius_to_counts(1e4) == 0


def test_reply_interleaved_in_a_stream_in_any_chunking():
    """0xD1 replies between 0xC2 records are picked out; no record is lost (random chunks)."""
    rng = np.random.default_rng(5)
    records = [p.encode_record(0xC2, rng.normal(size=6).astype(np.float32).tolist(), 625 * k)
               for k in range(200)]
    temps = {k: p.encode_temperature_reply(rng.integers(1800, 2400, 4), 625 * k)
             for k in (3, 50, 51, 199)}
    stream = b''.join(r + temps.get(k, b'') for k, r in enumerate(records))
    for _ in range(20):
        parser = StreamParser()
        cuts = np.sort(rng.integers(0, len(stream), size=40))
        out = []
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(stream)]):
            out += parser.feed(stream[a:b])
        out += parser.flush()
        assert [x for x in out if x[0] == 0xC2] == records
        assert [x for x in out if x[0] == 0xD1] == list(temps.values())
        assert parser.stats.rejected_bytes == 0 and parser.stats.resyncs == 0
