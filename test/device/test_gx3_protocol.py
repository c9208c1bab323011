"""3DM-GX3-25 protocol layer: real captures, encode/decode round trips, stream framing."""

import os
import random
import struct

from conftest import SHARED_DATA
from imu_allan.device import gx3_protocol as p
from imu_allan.device.gx3_stream import parse_bytes, StreamParser
from imu_allan.errors import InputError
from imu_allan.formats.gx3raw import read_gx3raw
import numpy as np
import pytest
import yaml

DATA = str(SHARED_DATA / 'gx3_25_captures')
needs_data = pytest.mark.skipif(not os.path.isdir(DATA),
                                reason=f'real GX3-25 captures not found at {DATA}')


def capture(name):
    """Bytes of one real capture file."""
    with open(os.path.join(DATA, name), 'rb') as stream:
        return stream.read()


# ------------------------------------------------------------------------------ real captures

@needs_data
def test_first_mopak_exact_values():
    """Every field of the 5 real 0xCB packets equals the OOI parser's expected values."""
    with open(os.path.join(DATA, 'first_mopak.result.yml'), encoding='utf-8') as stream:
        expected = yaml.safe_load(stream)['data']
    packets, stats = parse_bytes(capture('first.mopak.log'))
    assert len(packets) == len(expected) == 5
    assert stats.rejected_bytes == 0 and stats.bad_checksums == 0 and stats.resyncs == 0
    for packet, exp in zip(packets, expected):
        rec = p.decode_record(packet)
        assert rec.code == 0xCB
        assert rec.timer == exp['mopak_timer']
        got = dict(zip(('mopak_accelx', 'mopak_accely', 'mopak_accelz'), rec.fields['accel']))
        got.update(zip(('mopak_ang_ratex', 'mopak_ang_ratey', 'mopak_ang_ratez'),
                       rec.fields['gyro']))
        got.update(zip(('mopak_magx', 'mopak_magy', 'mopak_magz'), rec.fields['mag']))
        for key, value in got.items():
            # The reference values are the float32 values printed with 17 digits: exact.
            assert value == float(exp[key]), key


@needs_data
def test_noise_capture_loses_nothing():
    """3 junk bytes inserted: all 5 packets recovered, identical to the clean capture."""
    clean, _ = parse_bytes(capture('first.mopak.log'))
    noisy, stats = parse_bytes(capture('noise.mopak.log'))
    assert noisy == clean
    assert stats.rejected_bytes == 3 and stats.resyncs == 1 and stats.bad_checksums == 0


@needs_data
def test_bad_checksum_capture_rejects_exactly_two():
    """The 7-packet cut-out: 5 good packets kept, exactly the 2 damaged ones rejected."""
    data = capture('20140313_191853_bad_chksum.3dmgx3.log')
    packets, stats = parse_bytes(data)
    assert len(packets) == 5 and stats.bad_checksums == 2
    assert stats.rejected_bytes == 2 * 43
    assert [p.timer_of(x) for x in packets] == [11409586 + 6250 * k for k in range(5)]
    samples = read_gx3raw(os.path.join(DATA, '20140313_191853_bad_chksum.3dmgx3.log'))
    assert samples.n == 5
    assert any('2 bad checksums' in w for w in samples.warnings)


@needs_data
def test_full_capture_mixed_records():
    """81 0xCB and 67 0xCF packets; the reader takes the 6-axis 0xCB records."""
    packets, stats = parse_bytes(capture('20140313_191853.3dmgx3.log'))
    codes = [x[0] for x in packets]
    assert codes.count(0xCB) == 81 and codes.count(0xCF) == 67
    assert stats.rejected_bytes == 0
    samples = read_gx3raw(os.path.join(DATA, '20140313_191853.3dmgx3.log'))
    assert samples.n == 81 and samples.axes == p_axes()
    assert np.allclose(np.diff(samples.t), 0.1)
    # A unit at rest: |accel| is about 1 g, |mag| a plausible Earth field (20..70 uT).
    norm = np.linalg.norm(samples.data[:, 3:], axis=1)
    assert np.all(np.abs(norm - 9.80665) < 0.5)
    mag = np.linalg.norm(np.column_stack([samples.extra[k] for k in ('mag_x', 'mag_y',
                                                                     'mag_z')]), axis=1)
    assert np.all((mag > 20e-6) & (mag < 70e-6))


def p_axes():
    """Return the package axis order."""
    from imu_allan.core.units import AXES
    return AXES


@needs_data
def test_rollover_capture():
    """u32 rollover between packets 5 and 6: time keeps increasing by the real 6000 ticks."""
    samples = read_gx3raw(os.path.join(DATA, '20140313_191853_rollover.3dmgx3.log'))
    ticks = np.round(samples.t * p.TICKS_PER_SECOND).astype(np.int64)
    assert list(np.diff(ticks)) == [6000] * 5 + [6250]
    assert ticks[5] == 1 << 32
    assert not any('reset' in w for w in samples.warnings)


@needs_data
def test_timer_reset_capture():
    """Timer reset to 0: flagged, bridged with the previous spacing, time stays monotonic."""
    samples = read_gx3raw(os.path.join(DATA, '20140313_191853_timer_reset.3dmgx3.log'))
    ticks = np.round(samples.t * p.TICKS_PER_SECOND).astype(np.int64)
    assert list(np.diff(ticks)) == [6250] * 6
    assert any('reset' in w for w in samples.warnings)


@needs_data
def test_reader_units_match_decoded_values():
    """Reader output = decoded float32 values times gravity (accel), unchanged (rate), 1e-4."""
    samples = read_gx3raw(os.path.join(DATA, 'first.mopak.log'))
    rec = p.decode_record(parse_bytes(capture('first.mopak.log'))[0][0])
    assert samples.data[0, 0] == rec.fields['gyro'][0]
    assert samples.data[0, 3] == rec.fields['accel'][0] * 9.80665
    assert samples.extra['mag_z'][0] == rec.fields['mag'][2] * 1e-4
    assert samples.t[0] == 33456 / 62500


def test_reader_errors(tmp_path):
    """Unreadable, empty and packet-less files raise InputError naming the file."""
    with pytest.raises(InputError, match='cannot read'):
        read_gx3raw(tmp_path / 'missing.bin')
    empty = tmp_path / 'empty.bin'
    empty.write_bytes(b'')
    with pytest.raises(InputError, match='empty'):
        read_gx3raw(empty)
    junk = tmp_path / 'junk.bin'
    junk.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match='no 3DM-GX3-25 IMU data packets') as info:
        read_gx3raw(junk)
    assert str(junk) in str(info.value)


# ------------------------------------------------------------------------ worked byte examples

def test_worked_examples_from_reference():
    """The command byte strings and reply examples of the DCP manual."""
    c2 = bytes.fromhex('C2 3C23D70A BCA3D70A BF7F7CEE 3A83126F BB03126F 3A03126F 12345678 0B39')
    assert p.encode_record(0xC2, [0.01, -0.02, -0.998, 0.001, -0.002, 0.0005],
                           0x12345678) == c2
    le = p.encode_record(0xC2, [0.01, -0.02, -0.998, 0.001, -0.002, 0.0005], 0x12345678,
                         little_endian=True)
    assert le.hex().upper().startswith('C20AD7233C') and le[-6:] == c2[-6:]
    rec = p.decode_record(le, little_endian=True)
    assert rec.fields['accel'] == struct.unpack('>3f', c2[1:13])
    ten_s = p.encode_record(0xC2, [0, 0, -1, 0, 0, 0], 625000)
    assert ten_s.hex() == 'c2' + '00' * 8 + 'bf800000' + '00' * 12 + '00098968' + '02fb'
    assert p.cmd_continuous(0xC2) == bytes.fromhex('C4 C1 29 C2')
    assert p.encode_continuous_reply(0xC2, 625000) == bytes.fromhex('C4 C2 00 09 89 68 02 80')
    assert p.encode_continuous_reply(0, 625000) == bytes.fromhex('C4 00 00 09 89 68 01 BE')
    assert p.cmd_stop_continuous() == bytes.fromhex('FA 75 B4')
    assert p.cmd_sampling_settings(p.SamplingSettings(decimation=10)) == bytes.fromhex(
        'DB A8 B9 01 00 0A 00 03 0F 11 00 0A 00 0A 00 00 00 00 00 00')
    assert p.cmd_read_sampling_settings() == bytes.fromhex('DB A8 B9 00') + bytes(16)
    assert p.cmd_comm_settings(921600) == bytes.fromhex('D9 C3 55 01 01 00 0E 10 00 02 00')
    assert p.encode_comm_reply(921600) == bytes.fromhex('D9 01 00 0E 10 00 02 00 00 FA')
    assert p.encode_firmware_reply(1130) == bytes.fromhex('E9 00 00 04 6A 01 57')
    assert p.encode_mode_reply(1) == bytes.fromhex('D4 01 00 D5')
    assert p.encode_timer_reply(0) == bytes.fromhex('D7 00 00 00 00 00 D7')
    assert p.cmd_timer(1, 0) == bytes.fromhex('D7 C1 29 01 00 00 00 00')


def test_reply_round_trips():
    """Encode then decode every reply the driver uses; checksums validated."""
    assert p.decode_continuous_reply(p.encode_continuous_reply(0xCC, 2**32 - 1)) == \
        (0xCC, 2**32 - 1)
    s = p.SamplingSettings(decimation=4, flags=0x0002, filter_window=20, mag_window=9,
                           up_compensation=100, north_compensation=999, mag_power=1)
    assert p.decode_sampling_reply(p.encode_sampling_reply(s)) == s
    assert p.decode_comm_reply(p.encode_comm_reply(460800)) == (1, 460800, 2)
    assert p.decode_firmware_reply(p.encode_firmware_reply(1130)) == (1130, '1.1.30')
    assert p.firmware_text(1127) == '1.1.27'
    assert p.decode_device_id_reply(p.encode_device_id_reply(2, '3DM-GX3-25')) == \
        (2, '3DM-GX3-25')
    assert p.encode_device_id_reply(2, '3DM-GX3-25')[2:18] == b'      3DM-GX3-25'
    assert p.decode_mode_reply(p.encode_mode_reply(2)) == 2
    assert p.decode_timer_reply(p.encode_timer_reply(12345)) == 12345
    bad = bytearray(p.encode_firmware_reply(1130))
    bad[3] ^= 1
    with pytest.raises(ValueError, match='checksum'):
        p.decode_firmware_reply(bytes(bad))
    assert p.checksum_ok(p.ERROR_REPLY)


@pytest.mark.parametrize('code', [0xC2, 0xC8, 0xCB, 0xCC, 0xCE, 0xCF, 0xDF])
def test_record_round_trip_single_and_batch(code):
    """Random float32 values survive encode -> decode_record and decode_records exactly."""
    rng = np.random.default_rng(code)
    n = sum(k for _, k in p.DATA_RECORDS[code])
    values = rng.normal(size=(20, n)).astype(np.float32)
    timers = rng.integers(0, 2**32, size=20)
    packets = [p.encode_record(code, v.tolist(), int(t)) for v, t in zip(values, timers)]
    assert all(len(x) == p.REPLY_LENGTHS[code] and p.checksum_ok(x) for x in packets)
    rec = p.decode_record(packets[3])
    assert rec.timer == timers[3]
    assert np.array_equal(np.concatenate([rec.fields[k] for k, _ in p.DATA_RECORDS[code]]),
                          values[3])
    batch = p.decode_records(code, packets)
    assert np.array_equal(batch['timer'], timers)
    assert np.array_equal(np.hstack([batch[k] for k, _ in p.DATA_RECORDS[code]]), values)


def test_rates_and_bandwidth_table():
    """Decimation mapping and the DCP-GX3 Table 5 limits (31-byte records), longer records."""
    assert p.decimation_for_rate(100) == 10 and p.decimation_for_rate(1000) == 1
    assert p.decimation_for_rate(0.5) == 1000 and p.decimation_for_rate(333) == 3
    assert [p.max_rate(b) for b in p.BAUD_RATES] == [250.0, 1000 / 3, 500.0, 1000.0]
    assert p.min_decimation(115200, 79) == 7       # 0xCC: 100 Hz fits, 250 Hz does not
    assert p.max_rate(921600, 79) == 1000.0 and p.max_rate(115200, 79) == 1000 / 7
    with pytest.raises(ValueError):
        p.min_decimation(9600)
    with pytest.raises(ValueError):
        p.decimation_for_rate(0)


def test_timer_unwrapper():
    """Rollover adds 2**32; a big backwards step is a reset bridged with the last step."""
    u = p.TimerUnwrapper(max_gap_ticks=62500)
    seq = [2**32 - 20, 2**32 - 10, 0, 10, 5, 15]
    out = [u.update(v) for v in seq]
    assert out[:4] == [2**32 - 20, 2**32 - 10, 2**32, 2**32 + 10]
    assert u.rollovers == 1 and u.resets == 1
    assert out[4] == 2**32 + 20 and out[5] == 2**32 + 30


def random_timer_batches(rng, n=3000):
    """
    Raw u32 timer values in random batches: even 62/63-tick steps, gaps, repeats, rollovers.

    Also resets (a big backwards step) and a start just below 2**32, so that both the batch
    path and the value-by-value path of TimerUnwrapper.update_many are taken.
    """
    steps = rng.choice([62, 63], size=n)
    steps[rng.random(n) < 0.02] *= rng.integers(2, 6)          # lost records
    steps[rng.random(n) < 0.01] = 0                            # repeated value
    raw = (2**32 - 40 * 62 + np.cumsum(steps)) % 2**32         # rolls over after 40
    for i in rng.choice(n, size=4, replace=False):             # timer resets
        raw[i:] = (raw[i:] - raw[i] + int(rng.integers(0, 1000))) % 2**32
    cuts = np.sort(rng.choice(np.arange(1, n), size=n // 6, replace=False))
    return [b.astype(np.int64) for b in np.split(raw, cuts)]


def test_timer_unwrapper_batches_equal_value_by_value():
    """
    update_many gives update()'s ticks, last step and counters, and steps from the last value.

    Batches with a backward step return None without changing anything (the caller then goes
    value by value); the others are taken at once.  Fixed seeds, exact integer comparison.
    """
    for seed in range(5):
        rng = np.random.default_rng(seed)
        ref, fast = p.TimerUnwrapper(), p.TimerUnwrapper()
        batched = 0
        for batch in random_timer_batches(rng):
            expect = [ref.update(int(v)) for v in batch]
            before = dict(vars(fast))
            got = fast.update_many(batch)
            if got is None:
                assert vars(fast) == before
                assert [fast.update(int(v)) for v in batch] == expect
                continue
            batched += 1
            ticks, steps = got
            assert ticks.tolist() == expect
            previous = [before['last'] if before['last'] is not None else expect[0]]
            assert steps == np.diff(previous + expect).tolist()
            for key in ('offset', 'last_raw', 'last', 'last_step', 'rollovers', 'resets'):
                assert getattr(fast, key) == getattr(ref, key), key
        assert batched > 400 and ref.rollovers == fast.rollovers >= 1
        assert ref.resets == fast.resets >= 1


@pytest.mark.parametrize('code', sorted(p.DATA_RECORDS))
def test_record_array_fields_equal_decode_records(code):
    """The named-field view gives decode_records' values and timers, without a copy."""
    rng = np.random.default_rng(code)
    n = sum(k for _, k in p.DATA_RECORDS[code])
    values = rng.normal(size=(7, n)).astype(np.float32)
    packets = [p.encode_record(code, v.tolist(), 1000 * i + 7) for i, v in enumerate(values)]
    data = b''.join(packets)
    ref = p.decode_records(code, packets)
    arr = p.record_array(code, data)
    assert arr.base is not None and arr['timer'].tolist() == ref['timer'].tolist()
    for name, _ in p.DATA_RECORDS[code]:
        assert np.array_equal(arr[name].astype(np.float64), ref[name].astype(np.float64))


# ---------------------------------------------------------------------------- stream framing

def make_stream(seed=1):
    """Build a mixed stream of records and replies; return its packet list."""
    rng = random.Random(seed)
    packets = []
    for k in range(40):
        code = rng.choice([0xC2, 0xCB, 0xCC, 0xC8, 0xCF])
        n = sum(j for _, j in p.DATA_RECORDS[code])
        packets.append(p.encode_record(code, [rng.uniform(-2, 2) for _ in range(n)], 625 * k))
    packets.insert(5, p.encode_continuous_reply(0xC2, 1))
    packets.insert(9, p.encode_device_id_reply(1, '6223.01234'))
    packets.insert(12, p.encode_sampling_reply(p.SamplingSettings()))
    return packets


def test_chunking_at_every_byte_boundary():
    """Split the stream into two at every position, and byte by byte: same packets."""
    packets = make_stream()
    data = b''.join(packets)
    assert parse_bytes(data)[0] == packets
    for cut in range(len(data) + 1):
        parser = StreamParser()
        got = parser.feed(data[:cut]) + parser.feed(data[cut:])
        assert got == packets, cut
    parser = StreamParser()
    got = []
    for k in range(len(data)):
        got += parser.feed(data[k:k + 1])
    assert got == packets and parser.stats.rejected_bytes == 0


def test_junk_corruption_and_truncation_with_random_chunks():
    """Junk between packets, flipped bytes and a truncated packet: all other packets kept."""
    rng = random.Random(7)
    packets = make_stream(3)
    pieces, expected, damaged = [], [], 0
    for k, pkt in enumerate(packets):
        junk = k % 7 == 3
        if junk:
            # Junk of non-header bytes between packets (forces a resync).
            pieces.append(bytes(rng.randrange(0, 0xC0) for _ in range(rng.randint(1, 9))))
        if k % 11 == 5:
            bad = bytearray(pkt)
            bad[rng.randrange(1, len(pkt) - 2)] ^= 0x5A
            pieces.append(bytes(bad))
            # A damaged packet right after junk cannot be told from junk: not counted.
            damaged += not junk
            continue
        pieces.append(pkt)
        expected.append(pkt)
    data = b''.join(pieces)
    for trial in range(20):
        parser = StreamParser()
        got, i = [], 0
        while i < len(data):
            step = rng.randint(1, 100)
            got += parser.feed(data[i:i + step])
            i += step
        parser.flush()
        assert got == expected, trial
        assert parser.stats.bad_checksums == damaged
        assert parser.stats.rejected_bytes == len(data) - sum(map(len, expected))


def test_flush_frames_packets_behind_a_false_header(tmp_path):
    """
    Junk whose header-like byte announces a packet longer than the rest of the stream.

    The real packets behind it come out of :meth:`StreamParser.flush` (and out of
    ``parse_bytes`` and the raw-capture reader), each counted once; only the junk is rejected.
    """
    tail = [p.encode_record(0xC2, [0.5 * k] * 6, 625 * k) for k in range(2)]
    junk = bytes([0xCC, 1, 2, 3])          # 0xCC announces 79 bytes; 4 + 2 x 31 remain
    head = p.encode_record(0xC2, [1.0] * 6, 0)
    data = head + junk + b''.join(tail)
    parser = StreamParser()
    got = parser.feed(data)
    assert got == [head] and parser.buffered == len(junk) + 62
    assert parser.flush() == tail and parser.buffered == 0
    assert parser.stats.packets == 3 and parser.stats.resyncs == 1
    assert parser.stats.rejected_bytes == len(junk) and parser.stats.bad_checksums == 0
    # A real truncated packet at the very end is still rejected as a whole.
    assert parser.feed(tail[0][:20]) == [] and parser.flush() == []
    assert parser.stats.rejected_bytes == len(junk) + 20
    assert parse_bytes(data)[0] == [head] + tail
    path = tmp_path / 'false_header.bin'
    path.write_bytes(data)
    assert len(read_gx3raw(str(path)).t) == 3


def test_garbage_flood_does_not_grow_buffer():
    """A long flood of header-like garbage is consumed; the buffer stays below one packet."""
    parser = StreamParser()
    rng = np.random.default_rng(0)
    for _ in range(50):
        parser.feed(rng.integers(0, 256, 4096, dtype=np.uint8).tobytes())
        assert parser.buffered < 79
    good = p.encode_record(0xC2, [0.0] * 6, 1)
    # Enough good packets in a row re-establish sync (the first may be shadowed by a partial
    # candidate that started in the garbage).
    got = parser.feed(good * 5)
    assert got[-1] == good and len(got) >= 3


def test_restricted_codes():
    """A parser limited to data codes ignores a valid 0xEA reply as junk."""
    reply = p.encode_device_id_reply(0, '6223')
    rec = p.encode_record(0xC2, [1.0] * 6, 5)
    parser = StreamParser(codes=[0xC2])
    assert parser.feed(reply + rec) == [rec]
    assert parser.stats.rejected_bytes == len(reply)
